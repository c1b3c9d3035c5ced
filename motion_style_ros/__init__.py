"""motion_style_ros: restyle streaming human motion capture in ROS 2.

Layers, each importing only from the ones before it (test/test_layers.py checks it):
core (numpy, scipy: motion, rotations, features) -> io (files: BVH, bags, layouts, URDF) ->
runtime (ONNX Runtime sessions, the live intake, trajectories, robot targets) -> evaluation
(judges, metrics) -> models (torch) -> training (torch; it exports through runtime and names the
judges of evaluation) -> nodes (rclpy; core, io and runtime only) -> cli (anything, heavy imports
inside the commands). Importing this package imports nothing heavy.
"""

import os

# numpy's OpenBLAS would spread the small matrix products of one streamed frame over every core,
# which costs more than it saves (about a third of a stylizer step on 2 cores). Set before numpy
# loads; a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"
