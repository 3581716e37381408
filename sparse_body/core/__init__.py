"""Body model, rotations, kinematics, sensor configurations, contacts and metrics (numpy only)."""
