"""ROS 2 nodes (with the CLI, the only layer that imports rclpy and message packages): thin shells
over core, io and runtime. What every node shares: :mod:`.process` (how its process runs and
ends), :mod:`.parameters` (declaring parameters and QoS), :mod:`.messages` (topics and JointState).
"""
