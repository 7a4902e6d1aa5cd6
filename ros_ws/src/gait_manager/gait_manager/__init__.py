"""Gait and feedforward manager (ROS-free core plus a thin ROS 2 node)."""
