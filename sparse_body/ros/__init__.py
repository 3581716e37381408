"""Thin rclpy nodes over the ROS-free core: tracker TF in, JointState, contacts and TF out."""
