"""Recording a run: CDR layouts from the message definitions (``cdr``), what each topic holds
of a sample (``messages``), the bag and its writer process
(``bag``), the rosbag2 MCAP file written many messages at a time (``mcap_bag``), the message
types without ROS (``bag_types``).
"""
