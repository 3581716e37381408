"""Files and message shapes without ROS: rosbag2 in and out (bagio), the newest-transform TF
cache (tf_cache), a pose as JointState / TF / contact values (output) and the body's URDF
(urdf). The nodes and the commands share them, so live and offline read and write alike."""
