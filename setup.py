"""Build script for motion_style_ros (ament_python: colcon, pip and `pip install -e .` use it alike)."""

import os
from glob import glob

from setuptools import find_packages, setup
from setuptools.command.install import install

package_name = 'motion_style_ros'
here = os.path.dirname(os.path.abspath(__file__))


def share_files(top):
    """Map every file under `top`/ to share/<package>/`top`/..., keeping sub-folders.

    A missing or empty folder yields nothing, so it never breaks a build.
    """
    entries = {}
    for path in sorted(glob(os.path.join(top, '**', '*'), recursive=True)):
        if os.path.isfile(path):
            target = os.path.join('share', package_name, os.path.dirname(path))
            entries.setdefault(target, []).append(path)
    return sorted(entries.items())


class InstallAndWarm(install):
    """`setup.py install`, what colcon's ament_python build runs, then the stream kernels compiled into
    the install's own numba cache, so that the first node started after `colcon build` does not wait
    for a compiler. A packaging build (--root: a wheel, a distribution's package) and
    MOTION_STYLE_NO_WARMUP=1 skip it; if it fails, the install says so and nodes compile on their
    first start."""

    def run(self):
        super().run()
        if self.root or os.environ.get('MOTION_STYLE_NO_WARMUP'):
            return
        import subprocess
        import sys

        code = ('import sys; sys.path.insert(0, sys.argv[1]); '
                'from motion_style_ros.runtime.warmup import warm_kernels; '
                'print(f"motion_style_ros: stream kernels compiled into the install in {warm_kernels():.1f} s")')
        done = subprocess.run([sys.executable, '-c', code, self.install_lib], cwd=self.install_lib, check=False)
        if done.returncode:
            print('motion_style_ros: the stream kernels were not compiled at install; nodes compile them '
                  'on their first start (or run: motion-style warmup)')


# setuptools wants paths relative to the project folder.
os.chdir(here)

setup(
    name=package_name,
    version='0.1.0',
    description='Restyle streaming human motion capture in ROS 2 (JointState, VMC/OSC, bags, BVH).',
    license='Apache-2.0',
    maintainer='motion_style_ros maintainers',
    maintainer_email='maintainers@example.org',
    keywords=['ROS', 'motion capture', 'style transfer'],
    classifiers=[
        'Intended Audience :: Developers',
        'Intended Audience :: Science/Research',
        'Programming Language :: Python :: 3',
        'Topic :: Scientific/Engineering :: Artificial Intelligence',
    ],
    python_requires='>=3.10',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={package_name: ['resources/*.csv', 'resources/*.json']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        *share_files('launch'),
        *share_files('config'),
        *share_files('models'),
        *share_files('urdf'),
    ],
    # Runtime needs no torch and no ROS wheel: on a ROS install rclpy and the messages come from
    # the distribution; elsewhere requirements-ros-wheels.txt brings them from PyPI.
    install_requires=[
        'numpy',
        # the core's per-pose arithmetic (core/kernels.py), compiled: a streamed frame's cost
        'numba',
        'scipy',
        'onnxruntime',
        'python-osc',
        'rosbags',
        'tqdm',
        'matplotlib',
        # robot body maps (runtime/robot_target.py); rosbags brings it too, but it is imported here
        'ruamel.yaml',
        # URDF files (robot targets, the canonical skeleton's description): parsing and FK
        'yourdfpy',
    ],
    extras_require={
        # torch==2.13.0 exactly: a looser spec can pull a multi-GB CUDA build.
        'train': ['torch==2.13.0', 'onnx'],
        # onnx builds the tests' stand-in models (test/onnx_fixtures.py); the runtime never imports it
        'test': ['pytest', 'onnx'],
    },
    # Package data (csv/json) and models are opened by path, so never install as a zipped egg.
    zip_safe=False,
    cmdclass={'install': InstallAndWarm},
    entry_points={
        'console_scripts': [
            'motion-style = motion_style_ros.cli.main:main',
            'bvh_player = motion_style_ros.nodes.bvh_player:main',
            'bag_player = motion_style_ros.nodes.bag_player:main',
            'recorder = motion_style_ros.nodes.recorder:main',
            'synthetic_performer = motion_style_ros.nodes.synthetic_performer:main',
            'learned_performer = motion_style_ros.nodes.learned_performer:main',
            'vmc_bridge = motion_style_ros.nodes.vmc_bridge:main',
            'stylizer = motion_style_ros.nodes.stylizer:main',
            'stylizer_managed = motion_style_ros.nodes.stylizer_managed:main',
            'relay = motion_style_ros.nodes.relay:main',
        ],
    },
)
