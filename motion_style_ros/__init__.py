"""motion_style_ros: restyle streaming human motion capture in ROS 2.

Layers, imports pointing downward only: core (numpy) -> io -> models/training (torch) ->
runtime (onnxruntime) -> evaluation -> nodes (rclpy) -> cli. Importing this package imports
nothing heavy.
"""

__version__ = "0.1.0"
