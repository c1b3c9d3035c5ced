"""Stick-figure rendering: picture sizes and content, GIF frame counts, and ``motion-style render``."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.render import render_gif, render_png

CLI = [sys.executable, "-m", "motion_style_ros.cli.main"]


@pytest.fixture(scope="module")
def cmu_walk(datasets):
    """One second of a CMU walk (BVH units) and the same on the canonical skeleton (metres)."""
    m = bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[1:121]
    return m, retarget(m, canonical())


def drawn_pixels(image):
    """Pixels of the left-limb blue and right-limb red (not grid grey or white)."""
    a = np.asarray(image.convert("RGB")).astype(int)
    blue = (a[..., 2] - a[..., 0] > 80)
    red = (a[..., 0] - a[..., 2] > 80)
    return blue.sum(), red.sum()


def test_png_strip_has_a_panel_per_pose_and_draws_both_skeletons(cmu_walk, tmp_path):
    path = tmp_path / "strip.png"
    render_png(list(cmu_walk), ["cmu", "canonical"], path, frames=3, dpi=100)
    image = Image.open(path)
    assert image.format == "PNG" and image.size == (3 * 240, 2 * 280)
    for row in range(2):  # each skeleton's row shows blue left limbs and red right ones
        blue, red = drawn_pixels(image.crop((0, row * 280, 720, (row + 1) * 280)))
        assert blue > 200 and red > 200, row


def test_gif_has_one_frame_per_output_tick_and_follows_the_walker(cmu_walk, tmp_path):
    path = tmp_path / "walk.gif"
    render_gif(list(cmu_walk), ["cmu", "canonical"], path, fps=10, dpi=50)
    image = Image.open(path)
    assert image.format == "GIF" and image.n_frames == 10  # 1 s at 10 fps
    assert image.size == (2 * 120, 140)
    # The camera follows the pelvis: the figure stays in the panel from the first frame to the last.
    for k in (0, image.n_frames - 1):
        image.seek(k)
        blue, red = drawn_pixels(image)
        assert blue > 20 and red > 20, k


def test_mismatched_titles_are_refused(cmu_walk, tmp_path):
    with pytest.raises(MotionStyleError, match="2 motions but 1 titles"):
        render_png(list(cmu_walk), ["only one"], tmp_path / "x.png")


def test_cli_renders_png_and_gif_with_retargeting(datasets, tmp_path):
    source = bvh.read(datasets / "xia-test/neutral_01_000.bvh")
    short = tmp_path / "walk.bvh"
    bvh.write(short, bvh.BvhClip(source.skeleton, source.channels, source.data[:60], source.frame_time))
    png = tmp_path / "walk.png"
    proc = subprocess.run(CLI + ["render", str(short), "-o", str(png), "--retarget", "--frames", "2"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert Image.open(png).size == (2 * 240, 2 * 280)  # the clip and its canonical version
    gif = tmp_path / "walk.gif"
    proc = subprocess.run(CLI + ["render", str(short), str(short), "-o", str(gif), "--fps", "8"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert Image.open(gif).n_frames == 4  # 0.5 s at 8 fps


@pytest.mark.parametrize("args, message", [
    (["missing.bvh", "-o", "{tmp}/x.png"], "missing.bvh: cannot read"),
    (["{tmp}/bad.bvh", "-o", "{tmp}/x.png"], "bad.bvh: motion data holds a non-number 'zero'"),
    (["{tmp}/bad.bvh", "-o", "{tmp}/x.jpg"], "x.jpg: output must end in .png or .gif"),
])
def test_cli_bad_input_is_one_error_line(tmp_path, args, message):
    (tmp_path / "bad.bvh").write_text(
        "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n"
        "End Site\n{\nOFFSET 0 1 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 zero 0\n"
    )
    proc = subprocess.run(CLI + ["render"] + [a.format(tmp=tmp_path) for a in args],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "x.png").exists()
