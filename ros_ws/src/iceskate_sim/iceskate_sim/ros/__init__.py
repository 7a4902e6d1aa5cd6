"""The ROS side: the lockstep's message codecs (``effort_cdr``, ``gait_state_cdr``,
``conversions``), the lockstep logic (``lockstep``), the simulator node, the controller-node
base and what every node shares (``simulator_node``, ``controller_node``, ``node_support``).
"""
