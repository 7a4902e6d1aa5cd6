"""Visual-lifting stabilising controller (ROS-free core plus a thin ROS 2 node)."""
