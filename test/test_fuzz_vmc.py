"""The VMC receiver's parsing fuzzed with Hypothesis (settings and examples as test_fuzz.py): OSC
datagrams as raw bytes, real frame bundles with bytes flipped, cut, spliced or repeated, and OSC
messages of any arguments at the VMC addresses. Whatever arrives: the assembler never raises, a
datagram never makes more than two frames, and every frame and every JointState the bridge's link
makes of one is finite (or the link's own one-line error)."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from test_fuzz import FUZZ, no_hang, outcome
from test_vmc import random_motion
from vmc_helpers import sender_frames, unity_humanoid

from motion_style_ros.io import vmc
from motion_style_ros.runtime.vmc_link import VmcLink

SENT = sender_frames(random_motion(4, spread=0.3), unity_humanoid())
BUNDLES = [vmc.frame_bundle(f, k / 60).dgram for k, f in enumerate(SENT)]
ADDRESSES = [vmc.BONE_ADDRESS, vmc.ROOT_ADDRESS, vmc.TIME_ADDRESS, vmc.OK_ADDRESS, vmc.BLEND_ADDRESS,
             vmc.APPLY_ADDRESS, "/VMC/Thru/x", "/other"]


def check(datagrams):
    asm, link = vmc.VmcFrameAssembler(), VmcLink()
    with no_hang():
        for k, data in enumerate(datagrams):
            frames = asm.feed_datagram(data)
            assert len(frames) <= 2
            for f in frames:
                assert all(np.isfinite(p).all() and np.isfinite(q).all() for p, q in f.bones.values())
                out = outcome(link.receive, f, 10**9 + k * 16_666_667)
                if out is not None:
                    assert np.isfinite(out[1]).all()
    return asm


@FUZZ
@given(st.lists(st.binary(max_size=2000), max_size=20))
def test_raw_bytes(datagrams):
    asm = check(BUNDLES[:2] + datagrams)
    assert asm.counts["frames"] >= 2


@st.composite
def damaged(draw):
    """A real frame bundle with bytes flipped, a cut, a splice of another bundle, or repeats."""
    data = bytearray(BUNDLES[draw(st.integers(0, len(BUNDLES) - 1))])
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "cut", "splice", "repeat"]))
        i = draw(st.integers(0, max(0, len(data) - 1)))
        if kind == "flip" and data:
            data[i] ^= draw(st.integers(1, 255))
        elif kind == "cut":
            data = data[:i]
        elif kind == "splice":
            other = BUNDLES[draw(st.integers(0, len(BUNDLES) - 1))]
            data = data[:i] + other[draw(st.integers(0, len(other) - 1)):]
        else:
            data = data + data[16:]  # the elements again: every key twice
    return bytes(data)


@FUZZ
@given(st.lists(damaged(), min_size=1, max_size=8))
def test_damaged_frame_bundles(datagrams):
    check(datagrams + BUNDLES)


arguments = st.lists(st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32), st.integers(-2**31, 2**31 - 1),
    st.text(st.characters(blacklist_characters="\x00"), max_size=20), st.sampled_from(sorted(vmc.HUMAN_BONES)),
    st.booleans()), max_size=16)


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(ADDRESSES), arguments), max_size=40), st.booleans())
def test_messages_of_any_arguments_at_the_vmc_addresses(messages, bundled):
    built = [vmc.build_message(a, args) for a, args in messages]
    datagrams = [vmc.bundle(built).dgram] if bundled else [m.dgram for m in built]
    check(BUNDLES[:1] + datagrams + BUNDLES[1:])
