"""Recording a run: CDR layouts from the message definitions (``cdr``), what each topic holds
of a sample (``messages``, with the /tf transforms of ``links``), the bag and its writer process
(``bag``), the message types without ROS (``bag_types``), many messages written at once
(``bag_bulk``).
"""
