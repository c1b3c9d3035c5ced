"""The package's parsers fuzzed with Hypothesis: whatever the bytes, a valid result or the package's
own one-line MotionStyleError, never another exception, a hang or a non-finite value.

Inputs are drawn near the valid (a well-formed file with a few tokens replaced, deleted, duplicated
or cut off, numbers such as NaN, 1e400, 5e-324 or ``1_0``, deep nesting) and as raw bytes.
Examples per test: ``MOTION_STYLE_FUZZ_EXAMPLES`` (default 120; derandomized, so CI is
reproducible); a longer run: ``MOTION_STYLE_FUZZ_EXAMPLES=5000 pytest test/test_fuzz.py``
(docs/reliability.md has one's figures).
"""

import contextlib
import json
import math
import os
import signal

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bags, bvh
from motion_style_ros.io.joint_state import JointStateLayout, default_names

EXAMPLES = int(os.environ.get("MOTION_STYLE_FUZZ_EXAMPLES", "120"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much, HealthCheck.large_base_example])
HANG_SECONDS = 10  # one parse of a small input taking this long is a hang


@contextlib.contextmanager
def no_hang():
    def hung(*_):
        raise AssertionError(f"a parse took over {HANG_SECONDS} s")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(HANG_SECONDS)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def outcome(fn, *args):
    """``fn(*args)``'s result, or None after the package's own one-line error; anything else fails."""
    with no_hang():
        try:
            return fn(*args)
        except MotionStyleError as exc:
            text = str(exc)
            assert text and "\n" not in text, repr(text)
            return None


def finite(*arrays) -> bool:
    return all(np.isfinite(np.asarray(a, dtype=np.float64)).all() for a in arrays)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


# --- strategies --------------------------------------------------------------------------------

ODD_NUMBERS = ["nan", "NaN", "inf", "-inf", "1e400", "-1e400", "5e-324", "1e-320", "1_0", "0x10",
               "\u0661\u0662", "+", "-", ".", "e5", "1e", "--1", "1.2.3", "0", "-0", "1e9", "1e10",
               "9" * 5000]


def numbers():
    return st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                     st.integers(-10**6, 10**6).map(str), st.sampled_from(ODD_NUMBERS))


def mutated(text: str, tokens: list[str]):
    """``text`` with a few tokens replaced, deleted, doubled, or cut at a character."""

    @st.composite
    def build(draw):
        words = text.split(" ")
        for _ in range(draw(st.integers(0, 3))):
            if not words:
                break
            i = draw(st.integers(0, len(words) - 1))
            op = draw(st.sampled_from(["replace", "delete", "double", "insert"]))
            if op == "replace":
                words[i] = draw(st.sampled_from(tokens) | numbers())
            elif op == "delete":
                del words[i:i + draw(st.integers(1, 4))]
            elif op == "double":
                words.insert(i, words[i])
            else:
                words.insert(i, draw(st.sampled_from(tokens) | numbers() | st.text(max_size=5)))
        out = " ".join(words)
        if draw(st.booleans()) and out:
            out = out[:draw(st.integers(0, len(out)))]
        return out

    return build()


BVH_TOKENS = ["HIERARCHY", "ROOT", "JOINT", "End", "Site", "{", "}", "OFFSET", "CHANNELS", "MOTION",
              "Frames:", "Frame", "Time:", "0", "3", "6", "7", *bvh._POSITION, *bvh._ROTATION, "Hips",
              "\n", "\x00", "\u00e9"]


@st.composite
def bvh_texts(draw):
    """A BVH file (a chain or a small tree of joints, a few frames), then mutated; now and then a
    hierarchy nested thousands deep."""
    deep = draw(st.sampled_from([False] * 9 + [True]))
    n = draw(st.sampled_from([150, 3000])) if deep else draw(st.integers(1, 5))
    chans = [draw(st.sampled_from([3, 6, 0])) if j else 6 for j in range(n)]
    lines = ["HIERARCHY"]
    depth = 0

    def count(n):
        return draw(numbers()) if not deep and draw(st.integers(0, 14)) == 0 else n

    for j in range(n):
        parent_closes = 0 if deep or j == 0 else draw(st.integers(0, depth - 1))
        for _ in range(parent_closes):
            lines.append("}")
            depth -= 1
        names = ("Xposition Yposition Zposition " if chans[j] == 6 else "") + "Zrotation Xrotation Yrotation"
        offset = " ".join(draw(numbers()) if not deep and draw(st.integers(0, 9)) == 0 else "1.5"
                          for _ in range(3))
        lines += [f"{'ROOT' if j == 0 else 'JOINT'} j{j}", "{", f"OFFSET {offset}",
                  f"CHANNELS {count(chans[j])} {names if chans[j] else ''}".strip()]
        depth += 1
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] if not deep else []
    lines += ["}"] * depth
    frames = 1 if deep else draw(st.integers(1, 4))
    lines += ["MOTION", f"Frames: {draw(numbers()) if draw(st.integers(0, 4)) == 0 else frames}",
              f"Frame Time: {draw(numbers()) if draw(st.integers(0, 4)) == 0 else '0.0083333'}"]
    width = sum(chans)
    for _ in range(frames):
        lines.append(" ".join(draw(numbers()) if draw(st.integers(0, 30)) == 0 else "12.5"
                              for _ in range(width)))
    text = " \n ".join(lines)
    return text if deep else draw(mutated(text, BVH_TOKENS))


def file_bytes(texts):
    """Texts as UTF-8, or raw bytes."""
    return st.one_of(texts.map(lambda t: t.encode("utf-8", "surrogatepass")), st.binary(max_size=3000))


# --- BVH ---------------------------------------------------------------------------------------

# What fuzzing found, kept as examples that every run tries first.
BVH = ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation "
       "Xrotation Yrotation\nJOINT Spine\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
       "End Site\n{\nOFFSET 0 1 0\n}\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.0083333\n"
       "1 2 3 4 5 6 7 8 9\n")
DEEP_BVH = ("HIERARCHY\n" + "".join(f"{'ROOT' if j == 0 else 'JOINT'} j{j}\n{{\nOFFSET 0 1 0\nCHANNELS 3 "
                                   "Zrotation Xrotation Yrotation\n" for j in range(3000))
            + "}\n" * 3000 + "MOTION\nFrames: 1\nFrame Time: 0.1\n" + "0 " * 9000 + "\n")


@FUZZ
@given(data=file_bytes(bvh_texts()))
@example(data=BVH.replace("Frames: 1", "Frames: nan").encode())  # ValueError from int()
@example(data=BVH.replace("Frames: 1", "Frames: inf").encode())  # OverflowError
@example(data=BVH.replace("OFFSET 0 1 0", "OFFSET nan 1 0", 1).encode())  # a NaN skeleton
@example(data=BVH.replace("Time: 0.0083333", "Time: 0.0").encode())  # header() took it
@example(data=BVH.replace("Time: 0.0083333", "Time: 5e-324").encode())  # an infinite rate
@example(data=BVH.replace(" 9\n", " 1_0\n").encode())  # read() took what check() refuses
@example(data=BVH.replace("CHANNELS 3", "CHANNELS " + "9" * 5000).encode())  # ValueError in check()
@example(data=DEEP_BVH.encode())  # RecursionError
def test_bvh_read_header_check(scratch, data):
    path = scratch / "clip.bvh"
    path.write_bytes(data)
    clip = outcome(bvh.read, path)
    if clip is not None:
        assert clip.n_frames >= 1 and clip.data.shape == (clip.n_frames, sum(map(len, clip.channels)))
        assert finite(clip.data, clip.skeleton.offsets, clip.frame_time) and clip.frame_time > 0
        assert math.isfinite(clip.fps) and clip.fps > 0
        motion = outcome(clip.to_motion, 0.01)
        assert motion is None or finite(motion.rotations, motion.positions)
    span = outcome(bvh.header, path)
    if span is not None:
        frames, frame_time = span
        assert frames >= 1 and math.isfinite(frame_time) and frame_time > 0
    problem = outcome(bvh.check, path)
    assert problem is None or (isinstance(problem, str) and problem and "\n" not in problem)
    if clip is not None:  # check() finds no problem in a file read() takes
        assert problem is None, problem


# --- JointState intake ---------------------------------------------------------------------------

CANONICAL = JointStateLayout.canonical()
NAMES = default_names()


@st.composite
def joint_states(draw):
    """One JointState as the stylizer gets it: names (the canonical ones, some changed), positions
    (a plausible pose with a few odd values), a stamp (sec int32, nanosec uint32) and a receipt."""
    names = list(NAMES)
    for _ in range(draw(st.integers(0, 2)) if draw(st.integers(0, 3)) == 0 else 0):
        i = draw(st.integers(0, len(names) - 1))
        op = draw(st.sampled_from(["drop", "double", "rename", "finger"]))
        if op == "drop":
            del names[i]
        elif op == "double":
            names.insert(i, names[i])
        elif op == "rename":
            names[i] = draw(st.text(max_size=8))
        else:
            names.append("LeftIndexProximal_rx")
    values = [draw(st.floats(-3.0, 3.0)) for _ in names]
    for _ in range(draw(st.integers(0, 2))):
        if values:
            values[draw(st.integers(0, len(values) - 1))] = draw(st.floats(allow_nan=True,
                                                                           allow_infinity=True))
    if draw(st.integers(0, 9)) == 0:
        values = values[:draw(st.integers(0, len(values)))]
    sec = draw(st.one_of(st.integers(1_700_000_000, 1_700_000_010), st.integers(-2**31, 2**31 - 1),
                         st.just(0)))
    nanosec = draw(st.integers(0, 2**32 - 1))
    return names, values, sec * 1_000_000_000 + nanosec, draw(st.integers(0, 50_000_000))


@FUZZ
@given(frames=st.lists(joint_states(), min_size=1, max_size=12), scale=st.sampled_from([1.0, 1e-3]))
def test_joint_state_intake(frames, scale):
    from motion_style_ros.runtime.intake import DROP_REASONS, Bounds, Dropped, Intake

    layout = CANONICAL
    if scale != 1.0:  # a layout whose scale makes small values large angles
        layout = JointStateLayout([d.__class__(d.name, d.index, scale, 0.0) for d in CANONICAL._dofs],
                                  source="scaled", passthrough=CANONICAL.passthrough)
    intake = Intake(Bounds(), 1 / 120)
    receipt = 1_700_000_000_000_000_000
    accepted = []
    for names, positions, stamp, step in frames:
        receipt += step
        with no_hang():
            try:  # as runtime/performer.py takes a frame
                values = intake.check_values(names, positions)
                try:
                    intake.check_angles(*layout.angles(names, values))
                    rotations, root = layout.decode(names, values)
                except MotionStyleError as exc:
                    raise Dropped("bad_names", str(exc)) from None
                frame = intake.admit(stamp, receipt, root)
            except Dropped as drop:
                assert drop.reason in DROP_REASONS and "\n" not in str(drop)
                continue
        assert finite(rotations, root, frame.root)
        np.testing.assert_allclose(np.linalg.norm(rotations, axis=-1), 1.0, atol=1e-9)
        assert np.abs(root).max() <= intake.bounds.max_root_distance
        if accepted and not frame.restart:
            assert frame.stamp_ns > accepted[-1]
        intake.commit(frame, stamp)
        accepted.append(frame.stamp_ns)


# --- layout YAML, body maps ----------------------------------------------------------------------

SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(),
                    st.text(max_size=10), st.sampled_from(NAMES[:8]))
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4)
                      | st.dictionaries(st.text(max_size=6) | st.integers(0, 3), inner, max_size=4),
                      max_leaves=12)


def yaml_text(value) -> str:
    import io

    from ruamel.yaml import YAML

    out = io.StringIO()
    YAML(typ="safe").dump(value, out)
    return out.getvalue()


@st.composite
def layout_maps(draw):
    joints = [{"name": draw(st.text(min_size=1, max_size=8)), "dof": draw(st.sampled_from(NAMES) | VALUES),
               **({"scale": draw(SCALARS)} if draw(st.booleans()) else {}),
               **({"offset": draw(SCALARS)} if draw(st.booleans()) else {})}
              for _ in range(draw(st.integers(0, 4)))]
    data = {"joints": joints}
    if draw(st.booleans()):
        data["unknown_names"] = draw(st.sampled_from(["error", "ignore"]) | VALUES)
    if draw(st.booleans()):
        data["passthrough"] = draw(st.lists(st.text(max_size=6), max_size=3) | VALUES)
    if draw(st.integers(0, 4)) == 0:
        data[draw(st.text(max_size=5) | st.integers())] = draw(VALUES)
    return data


YAML_TOKENS = ["joints:", "-", "name:", "dof:", "scale:", "offset:", "{", "}", "[", "]", ":", "&a",
               "*a", "!!python/object:os.system", "%YAML", "---", "\t", "\x00"]


def yaml_files(maps):
    return file_bytes(st.one_of(
        maps.map(yaml_text),
        maps.map(yaml_text).flatmap(lambda t: mutated(t, YAML_TOKENS)),
        st.sampled_from([3, 600]).map(lambda n: "[" * n + "]" * n),  # nesting
        st.just("a: &a [" + ", ".join(["*a"] * 9) + "]\nb: &b [" + ", ".join(["*a"] * 9) + "]\n"),
    ))


@FUZZ
@given(data=yaml_files(layout_maps()))
@example(data=b"joints:\n- {name: a, dof: []}\n")  # TypeError: unhashable
@example(data=b"joints:\n- {name: a, dof: root_tx}\n1: x\nb: y\n")  # TypeError from sorted()
@example(data=b'joints:\n- {name: "\\n", dof: null}\n')  # a newline in the error
@example(data=b"joints:\n- {name: a, dof: root_tx, scale: " + b"9" * 400 + b"}\n")  # OverflowError
@example(data=b"[" * 600 + b"]" * 600)  # RecursionError
@example(data=b"joints: " + b"9" * 5000)  # ValueError: an int of over 4300 digits
def test_layout_yaml(scratch, data):
    path = scratch / "layout.yaml"
    path.write_bytes(data)
    layout = outcome(JointStateLayout.from_yaml, path)
    if layout is not None:
        assert layout.names and len(set(layout.names)) == len(layout.names)
        assert finite(layout._scale, layout._offset) and (layout._scale != 0).all()
        values = np.zeros(len(layout.names))
        decoded = outcome(layout.decode, layout.names, values)  # a layout may leave DOFs out: fine
        assert decoded is None or finite(*decoded)


@st.composite
def body_maps(draw):
    from motion_style_ros.runtime.robot_body_map import MAP_KEYS

    keys = draw(st.lists(st.sampled_from(MAP_KEYS) | st.text(max_size=5) | st.integers(), max_size=4))
    return {k: draw(st.text(max_size=8) | VALUES) for k in keys}


@FUZZ
@given(data=yaml_files(body_maps()))
@example(data=b"1: a\nleft_kne: b\n")  # TypeError from sorted()
@example(data=b"9" * 5000)  # ValueError: an int of over 4300 digits
@example(data=b"[" * 600 + b"]" * 600)  # RecursionError
def test_body_map_yaml(scratch, data):
    from motion_style_ros.runtime.robot_body_map import MAP_KEYS, load_map

    path = scratch / "map.yaml"
    path.write_bytes(data)
    found = outcome(load_map, path)
    if found is not None:
        assert set(found) <= set(MAP_KEYS) and all(isinstance(v, str) for v in found.values())


# --- URDF --------------------------------------------------------------------------------------

URDF = """<robot name="r">
 <link name="base"><inertial><origin xyz="{com}"/><mass value="1"/></inertial>
  <collision><origin xyz="{shape_at}"/><geometry><box size="{box}"/></geometry></collision></link>
 <link name="leg"><visual><geometry><cylinder radius="{radius}" length="{length}"/></geometry></visual></link>
 <link name="foot"><collision><geometry><sphere radius="{radius}"/></geometry></collision></link>
 <joint name="hip" type="{kind}"><parent link="base"/><child link="leg"/>
  <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>
  <limit lower="{lower}" upper="{upper}" velocity="{velocity}" effort="10"/></joint>
 <joint name="knee" type="continuous"><parent link="leg"/><child link="foot"/>
  <origin xyz="0 0 -0.4"/><axis xyz="1 0 0"/></joint>
</robot>
"""
URDF_VALUES = {"com": "0 0 0.1", "shape_at": "0 0 0", "box": "0.2 0.1 0.05", "radius": "0.05",
               "length": "0.4", "kind": "revolute", "xyz": "0 0.1 -0.2", "rpy": "0 0 0", "axis": "0 1 0",
               "lower": "-1.5", "upper": "1.5", "velocity": "5"}
URDF_TOKENS = ["<robot>", "</robot>", "<link", "name=", '"', "/>", "<joint", 'type="prismatic"',
               'type="floating"', "<origin", "<limit", "<mimic", 'joint="hip"/>', "<!--", "&lt;",
               '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">]>', "&a;", "<?xml"]


@st.composite
def urdf_texts(draw):
    """The URDF above with a few attribute values odd (NaN, 1e400, two values for three, a word),
    then mutated."""
    values = dict(URDF_VALUES)
    for key in draw(st.lists(st.sampled_from(sorted(values)), max_size=3)):
        values[key] = draw(numbers() | st.lists(numbers(), min_size=0, max_size=4).map(" ".join)
                           | st.sampled_from(["fixed", "continuous", "planar", "x"]))
    return draw(mutated(URDF.format(**values).replace("\n", " \n "), URDF_TOKENS))


@FUZZ
@given(data=file_bytes(urdf_texts()))
@example(data=URDF.format(**{**URDF_VALUES, "box": "0.2 0.05"}).encode())  # ValueError: broadcast
@example(data=URDF.format(**{**URDF_VALUES, "xyz": "nan 0 0"}).encode())  # a NaN origin
@example(data=URDF.format(**{**URDF_VALUES, "rpy": "1e400 0 0"}).encode())  # a NaN rotation
@example(data=URDF.format(**{**URDF_VALUES, "axis": "0 0 0"}).encode())  # no axis
@example(data=URDF.format(**{**URDF_VALUES, "kind": "0.0", "axis": "1"}).encode())  # no joint type
@example(data=URDF.format(**{**URDF_VALUES, "lower": "nan", "velocity": "-1"}).encode())
def test_urdf_read(scratch, data):
    from motion_style_ros.io import urdf

    path = scratch / "robot.urdf"
    path.write_bytes(data)
    model = outcome(urdf.read, path)
    if model is not None:
        for j in model.joints:
            assert finite(j.origin, j.axis) and (j.kind not in urdf.MOVING or np.linalg.norm(j.axis) > 0), j
            assert not (math.isnan(j.lower) or math.isnan(j.upper) or math.isnan(j.velocity)), j
            assert j.lower <= j.upper and j.velocity > 0, j
        assert all(finite(p) for p in [*model.coms.values(), *model.shapes.values()])


# --- model cards, style banks --------------------------------------------------------------------

def json_files(values, tokens):
    texts = values.map(lambda v: json.dumps(v, allow_nan=True))
    return file_bytes(st.one_of(texts, texts.flatmap(lambda t: mutated(t, tokens)),
                                st.integers(1, 100_000).map(lambda n: "[" * n + "]" * n)))


JSON_TOKENS = ["{", "}", "[", "]", ":", ",", '"', "NaN", "Infinity", "-Infinity", "1e400", "null",
               "true", "\\ud800", '"\\u0000"']
JSON_VALUES = st.recursive(st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats()
                           | st.text(max_size=8),
                           lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=12)


@st.composite
def cards(draw):
    card = {"name": "stgcn", "kind": "stgcn", "styles": ["angry", "proud"], "neutral_style": "neutral",
            "fps": 30, "window": 60, "style_dim": 8, "frames_multiple": 4}
    for _ in range(draw(st.integers(0, 3))):
        card[draw(st.sampled_from(sorted(card)) | st.text(max_size=4))] = draw(JSON_VALUES)
    return card if draw(st.integers(0, 9)) else draw(JSON_VALUES)


def no_non_finite(value) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(no_non_finite(v) for v in value.values())
    if isinstance(value, list):
        return all(no_non_finite(v) for v in value)
    return True


@FUZZ
@given(data=json_files(cards(), JSON_TOKENS))
@example(data=b'{"window": NaN}')  # non-finite values
@example(data=b'{"fps": 1e400}')
@example(data=b'{"window": "48"}')  # what the runtime would index or count with
@example(data=b"[1, 2]")
@example(data=b"[" * 100_000 + b"]" * 100_000)  # RecursionError
def test_model_card(scratch, data):
    from motion_style_ros.runtime.onnx_model import CARD_TYPES, read_card

    (scratch / "model.json").write_bytes(data)
    card = outcome(read_card, scratch / "model.onnx")
    if card is not None:
        assert isinstance(card, dict) and no_non_finite(card)
        for key, kind in CARD_TYPES.items():
            if key in card:
                assert isinstance(card[key], kind[0]) and kind[1](card[key]), (key, card[key])


@st.composite
def banks(draw):
    entry = {"code": [0.1] * 4, "head": "angry", "clips": ["a.bvh"], "frames": 120,
             "probabilities": {"angry": 0.7, "proud": 0.3}}
    styles = {}
    for k in range(draw(st.integers(0, 3))):
        e = dict(entry)
        for _ in range(draw(st.integers(0, 2))):
            e[draw(st.sampled_from(sorted(entry)))] = draw(JSON_VALUES | st.sampled_from(
                [[math.nan] * 4, [1e308] * 4, {"angry": math.nan}, math.inf, -5, 1e300, [0.1] * 3]))
        styles[draw(st.sampled_from([f"mine{k}", "angry", "Bad Name", ""]))] = e
    bank = {"version": 1, "model": "stgcn", "model_digest": "abc", "styles": styles}
    for _ in range(draw(st.integers(0, 1))):
        bank[draw(st.sampled_from(sorted(bank)))] = draw(JSON_VALUES)
    return bank


BANK = ('{"version": 1, "model": "stgcn", "model_digest": "abc", "styles": {"mine": {"code": '
        '[0.1, 0.1, 0.1, 0.1], "head": "angry", "clips": ["a.bvh"], "frames": 120, '
        '"probabilities": {"angry": 0.7}}}}')


@FUZZ
@given(data=json_files(banks(), JSON_TOKENS))
@example(data=BANK.replace('{"angry": 0.7}', "null").encode())  # AttributeError
@example(data=BANK.replace("120", "Infinity").encode())  # OverflowError from int()
@example(data=BANK.replace("0.7", "NaN").encode())  # a NaN probability
@example(data=b"9" * 5000)  # ValueError: an int of over 4300 digits
@example(data=b"[" * 100_000 + b"]" * 100_000)  # RecursionError
def test_style_bank(scratch, data):
    from motion_style_ros.runtime import style_bank

    path = scratch / "bank.json"
    path.write_bytes(data)
    entries = outcome(style_bank.read, path, "abc", 4, ["angry", "proud"])
    if entries is not None:
        for name, entry in entries.items():
            assert style_bank.check_name(name, ["angry", "proud"]) == name
            assert len(entry.code) == 4 and finite(entry.code) and entry.head in ("angry", "proud", "mix")
            assert entry.frames >= 0 and all(isinstance(c, str) for c in entry.clips)
            assert finite(list(entry.probabilities.values()))


# --- bags: a decode check on any bytes -----------------------------------------------------------

@FUZZ
@given(data=st.one_of(st.binary(max_size=400), st.binary(max_size=300).map(lambda b: b"\x00\x01\x00\x00" + b)))
def test_joint_state_decode_check(data):
    store = bags.typestore()
    with no_hang():
        msg, why = bags.check_joint_state(store, data)
    if msg is None:
        assert why and "\n" not in why
    else:
        assert len(msg.name) == len(msg.position) and finite(msg.position, msg.velocity, msg.effort)


@pytest.fixture(scope="module")
def small_bag(scratch):
    """A 30-message bag's folder and its .mcap bytes."""
    records = [bags.JointStateRecord(1_700_000_000_000_000_000 + 10_000_000 * i, ["a", "b", "c"],
                                     np.array([i, -i, 0.5 * i], float)) for i in range(30)]
    bags.write_joint_states(scratch / "bag", records)
    return scratch / "bag", (scratch / "bag" / "bag.mcap").read_bytes()


@st.composite
def damage(draw, size):
    """Edits of a file of ``size`` bytes: (offset, bytes written there), and where it is cut."""
    edits = []
    for _ in range(draw(st.integers(0, 4))):
        at = draw(st.integers(0, size - 1))
        edits.append((at, draw(st.binary(min_size=1, max_size=64) | st.sampled_from(
            [b"\x00" * 512, b"\xff" * 8, b"\x05", b"\x06" + b"\xff" * 8]))))
    cut = draw(st.none() | st.integers(0, size))
    return edits, cut


@FUZZ
@given(data=st.data())
def test_damaged_bags(small_bag, data):
    folder, good = small_bag
    edits, cut = data.draw(damage(len(good)))
    damaged = bytearray(good)
    for at, chunk in edits:
        damaged[at:at + len(chunk)] = chunk
    damaged = bytes(damaged[:cut])
    (folder / "bag.mcap").write_bytes(damaged)
    try:
        for skip in (False, True):
            contents = outcome(bags.read_checked, folder, None, skip)
            if contents is not None:
                assert skip or damaged == good or not contents.damage
                assert contents.skipped is None or contents.skipped >= 0
                store = bags.typestore()
                for _, _, raw, _ in contents.messages:
                    msg = store.deserialize_cdr(raw, bags.JOINT_STATE)
                    assert len(msg.name) == len(msg.position) and finite(msg.position)
    finally:
        (folder / "bag.mcap").write_bytes(good)
