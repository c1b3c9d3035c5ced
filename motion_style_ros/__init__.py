"""motion_style_ros: restyle streaming human motion capture in ROS 2.

Layers, imports pointing downward only: core (numpy) -> io -> models/training (torch) ->
runtime (onnxruntime) -> evaluation -> nodes (rclpy) -> cli. Importing this package imports
nothing heavy.
"""

import os

# numpy's OpenBLAS would spread the small matrix products of one streamed frame over every core,
# which costs more than it saves (about a third of a stylizer step on 2 cores). Set before numpy
# loads; a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"
