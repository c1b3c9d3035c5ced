"""The reference Style-ERD timing stand-in: its size matches the reference's defaults, one streaming
step has the reference's output, and the recurrent state carries between steps."""

import pytest

torch = pytest.importorskip("torch", reason="the reference ERD is torch: pip install '.[train]'")

from motion_style_ros.models.reference_erd import (
    ReferenceERD,
    ReferenceSizes,
    ReferenceStream,
    reference_step_times,
)

# Parameter count at the reference's defaults (input 124 + 60 + 60 + 4 + 5 + 7 = 260, latent 32,
# 7 styles, 5 contents, encoder 2, decoder 4, neutral LSTM 4 layers, residual LSTMs 6 layers):
#   encoder  260*130+130 = 33,930; 130*64+64 = 8,384; 64*32+32 = 2,080         ->  44,394
#   LSTM layer 32->32: 4*32*(32+32) + 2*4*32 = 8,448
#   neutral  4 * 8,448 = 33,792, initial h,c 2*4*5*32 = 1,280                   ->  35,072
#   residual 7 * 6 * 8,448 = 354,816, initial h,c 2*6*7*32 = 2,688              -> 357,504
#   decoder  39*58+58 = 2,320; 58*86+86 = 5,074; 86*128+128 = 11,136;
#            heads 128*124+124 = 15,996, 128*60+60 = 7,740 (position), 7,740 (velocity)
#                                                                               ->  50,006
#   total 44,394 + 35,072 + 357,504 + 50,006 = 486,976
REFERENCE_PARAMETERS = 486_976


@pytest.fixture(scope="module")
def model():
    return ReferenceERD(seed=0)


def _frames(n: int, seed: int = 3) -> "torch.Tensor":
    return torch.randn(n, ReferenceSizes().n_in, generator=torch.Generator().manual_seed(seed))


def test_sizes_and_parameter_count(model):
    s = model.sizes
    assert (s.n_in, s.n_out) == (260, 244)
    assert s.encoder_widths == (130, 64)
    assert s.decoder_widths == (58, 86, 128)
    assert sum(p.numel() for p in model.parameters()) == REFERENCE_PARAMETERS


def test_step_output(model):
    stream = ReferenceStream(model)
    with torch.inference_mode():
        out = stream.step(_frames(1)[0])
    assert out.shape == (244,)
    assert torch.isfinite(out).all()
    quats = out[:124].reshape(31, 4)
    torch.testing.assert_close(quats.norm(dim=-1), torch.ones(31))


def test_state_carries_and_resets(model):
    stream = ReferenceStream(model)
    frame = _frames(1)[0]
    with torch.inference_mode():
        first = stream.step(frame)
        second = stream.step(frame)
        stream.reset()
        again = stream.step(frame)
    assert not torch.allclose(first, second)  # LSTM state moved on
    torch.testing.assert_close(first, again)  # reset = the learned initial state


@pytest.mark.parametrize("style,mix", [(4, False), (None, False), (2, True)])
def test_streaming_equals_whole_clip(model, style, mix):
    """Frame by frame with carried state = the reference's whole-clip pass (no window needed)."""
    frames = _frames(12)
    stream = ReferenceStream(model, content=1, style=style, mix=mix)
    with torch.inference_mode():
        stepped = torch.stack([stream.step(f) for f in frames])
        state = model.initial_state(1, stream.branches)
        whole, _ = model(frames[None], state, stream.branches, stream.weights)
    torch.testing.assert_close(stepped, whole[0], atol=1e-5, rtol=1e-5)


def test_step_times_restores_threads():
    before = torch.get_num_threads()
    p50, p99 = reference_step_times(threads=1, calls=20, warmup=2)
    assert 0 < p50 <= p99
    assert torch.get_num_threads() == before
