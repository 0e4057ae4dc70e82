"""What runs a scheme on a table: the station.yaml configuration, the scheme compiler (gimbal
inverse kinematics, operator steps), the plan's step types, the sequencer that executes them
through the drivers, the IMU stream, hand-scheme recording and the live display."""
