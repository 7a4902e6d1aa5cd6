"""Simulator of the 17-joint ice-skating humanoid (ROS-free core plus thin ROS 2 nodes)."""
