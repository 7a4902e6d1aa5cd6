"""Recording a run: the bag's samples, messages, encoding and writer (``bag``), the message types
without ROS (``bag_types``), many messages written at once (``bag_bulk``).
"""
