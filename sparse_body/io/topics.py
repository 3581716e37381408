"""The topics of the bags this package writes, and how their chunks may be compressed: plain
names, imported by the command line without the bag libraries."""

TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
JOINT_STATES_TOPIC, CONTACTS_TOPIC, STATUS_TOPIC = "/joint_states", "/foot_contacts", "/estimate_status"
DESCRIPTION_TOPIC = "/robot_description"
ROBOT_PREFIX = "robot/"  # the robot's TF frames: its base link is robot/<base link>
ROBOT_DESCRIPTION_TOPIC = "/robot/robot_description"  # its URDF, latched (process --robot)
ROBOT_JOINT_STATES_TOPIC = "/robot/joint_states"  # the humanoid robot's joints (process --robot)
ESTIMATE_TOPICS = (JOINT_STATES_TOPIC, CONTACTS_TOPIC, STATUS_TOPIC, TF_TOPIC, DESCRIPTION_TOPIC)
# MCAP chunk compression, as rosbag2's MCAP storage writes it (its zstd presets): every MCAP
# reader decompresses it (ros2 bag, Foxglove, the mcap tools, rosbags), and the bag's metadata
# says compression none, its file being an ordinary MCAP file. zstd: an estimate bag to about a
# tenth; lz4: faster, larger.
COMPRESSIONS = ("zstd", "lz4", "none")
