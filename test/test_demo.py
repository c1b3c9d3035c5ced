"""The README's demo command, end to end in a subprocess."""

import subprocess
import sys

from PIL import Image


def test_demo_retargets_judges_and_renders(tmp_path, datasets):
    out = tmp_path / "demo"
    result = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "demo", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stdout.splitlines()
    cmu = next(line for line in lines if line.startswith("CMU 02_01 walk"))
    assert "walk (" in cmu  # the content judge recognises the retargeted CMU walk
    assert "style elderly" in next(line for line in lines if line.startswith("Bandai"))
    with Image.open(out / "demo.png") as png:
        assert png.width > 600 and png.height > 400
    with Image.open(out / "demo.gif") as gif:
        assert gif.n_frames >= 30
