"""Bounded reads of user-named files: one line for what cannot be a file of that kind, never a hang."""

import os

import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files


def test_a_regular_file_is_read(tmp_path):
    p = tmp_path / "a.bvh"
    p.write_bytes(b"HIERARCHY\n")
    assert files.read_bytes(p, "bvh") == b"HIERARCHY\n"
    assert files.read_text(p, "bvh") == "HIERARCHY\n"


@pytest.mark.parametrize("make, reason", [
    (lambda d: "/dev/zero", "is a device"),
    (lambda d: str(d), "is a directory"),
    (lambda d: (os.mkfifo(d / "fifo"), str(d / "fifo"))[1], "is a FIFO"),
    (lambda d: str(d / "missing.bvh"), "cannot read (No such file or directory)"),
])
def test_what_is_not_a_regular_file_is_refused_in_one_line_without_opening_it(tmp_path, make, reason):
    path = make(tmp_path)
    with pytest.raises(MotionStyleError) as exc:
        files.read_bytes(path, "bvh")  # a FIFO with no writer would block open(): it must not be opened
    assert reason in str(exc.value) and "\n" not in str(exc.value)
    assert str(path) in str(exc.value)


def test_a_file_over_its_kinds_limit_is_refused_and_the_limit_can_be_raised(tmp_path, monkeypatch):
    p = tmp_path / "big.bvh"
    with open(p, "wb") as f:  # sparse: 2 GiB without writing them
        f.truncate(2 * 2**30)
    with pytest.raises(MotionStyleError, match=r"2048\.0 MiB is over the 256 MiB limit for a bvh "
                                               r"\(raise it with MOTION_STYLE_MAX_BVH_MB\)"):
        files.check(p, "bvh")
    small = tmp_path / "small.yaml"
    small.write_bytes(b"x" * 2048)
    monkeypatch.setenv("MOTION_STYLE_MAX_LAYOUT_MB", "0.001")
    with pytest.raises(MotionStyleError, match="over the 0.001 MiB limit for a layout"):
        files.read_text(small, "layout")
    monkeypatch.setenv("MOTION_STYLE_MAX_LAYOUT_MB", "1")
    assert len(files.read_text(small, "layout")) == 2048
    monkeypatch.setenv("MOTION_STYLE_MAX_LAYOUT_MB", "lots")
    with pytest.raises(MotionStyleError, match="MOTION_STYLE_MAX_LAYOUT_MB='lots' is not a number"):
        files.read_text(small, "layout")


def _readers():
    from motion_style_ros.io import bvh, urdf
    from motion_style_ros.io.joint_state import JointStateLayout
    from motion_style_ros.runtime import onnx_model, robot_body_map, style_bank

    return {"bvh": bvh.read, "bvh header": bvh.header, "model": onnx_model.model_path,
            "style bank": style_bank._load, "layout": JointStateLayout.from_yaml,
            "body map": robot_body_map.load_map, "urdf": urdf.read}


@pytest.mark.parametrize("reader", sorted(_readers()))
@pytest.mark.parametrize("special", ["/dev/zero", "fifo", "directory"])
def test_every_reader_of_a_user_named_file_refuses_what_is_not_a_regular_file(reader, special, tmp_path):
    path = {"/dev/zero": "/dev/zero", "fifo": str(tmp_path / "fifo"), "directory": str(tmp_path)}[special]
    if special == "fifo":
        os.mkfifo(path)
    with pytest.raises(MotionStyleError, match="must be a regular file") as exc:
        _readers()[reader](path)
    assert "\n" not in str(exc.value)
