"""The estimated body as a humanoid robot's joints (issue 54): a robot read from its URDF
(urdf_model), which of its links follow which human joints (mapping, a small YAML per robot)
and the solver that turns each body pose into the robot's joint angles within their limits,
feet kept on the floor while planted (retarget). ROS-free: the node, the offline bag and the
measurements share it."""
