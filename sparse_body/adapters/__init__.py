"""Real tracker sources, usable without ROS: VMC over OSC/UDP, serial IMU and Lighthouse
devices, their clocks, and T-pose calibration. The tracker bridge node turns them into TF."""
