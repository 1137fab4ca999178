"""The streaming GRU's weight average (train/stream_gru_ema.py): the update rule against its closed
form, buffers copied, the model's own weights back after validation, and the setting's bounds."""

from __future__ import annotations

import pytest
import torch

from quadfdi.core.errors import QuadfdiError


class _Tiny(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.lin = torch.nn.Linear(2, 1)
        self.register_buffer("mean", torch.zeros(2))


def _set(model: _Tiny, value: float) -> None:
    with torch.no_grad():
        model.lin.weight.fill_(value)
        model.lin.bias.fill_(-value)
        model.mean.fill_(value)


def test_average_follows_the_warmed_up_decay():
    from quadfdi.train.stream_gru_ema import WeightAverage

    model = _Tiny()
    _set(model, 1.0)
    ema = WeightAverage(model, 0.5)
    expect = 1.0
    for n, value in enumerate([3.0, 5.0, 7.0, 11.0]):
        _set(model, value)
        d = min(0.5, (1 + n) / (10 + n))  # 0.1, 0.18.., 0.25, 0.30..: below 0.5, the warm-up rules
        assert ema.rate() == pytest.approx(d)
        ema.update()
        expect = d * expect + (1 - d) * value
        assert ema.shadow["lin.weight"] == pytest.approx(torch.full((1, 2), expect))
        assert ema.shadow["lin.bias"] == pytest.approx(torch.full((1,), -expect))
        assert torch.equal(ema.shadow["mean"], torch.full((2,), value))  # a buffer: copied, not averaged
    for _ in range(200):
        ema.update()
    assert ema.rate() == 0.5  # past the warm-up the decay is the setting
    assert ema.shadow["lin.weight"] == pytest.approx(torch.full((1, 2), 11.0))


def test_swapped_validates_the_average_and_gives_the_weights_back():
    from quadfdi.train.stream_gru_ema import WeightAverage

    model = _Tiny()
    _set(model, 2.0)
    ema = WeightAverage(model, 0.9)
    _set(model, 4.0)
    with ema.swapped():
        assert torch.equal(model.lin.weight, torch.full((1, 2), 2.0))
    assert torch.equal(model.lin.weight, torch.full((1, 2), 4.0))
    with pytest.raises(RuntimeError), ema.swapped():
        raise RuntimeError("validation failed")
    assert torch.equal(model.lin.weight, torch.full((1, 2), 4.0))  # restored on the way out of an error too


def test_bad_ema_settings_are_refused():
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_ema import WeightAverage

    for bad in (-0.1, 1.0):
        with pytest.raises(QuadfdiError, match="ema_decay"):
            StreamFitConfig(ema_decay=bad).validate()
    StreamFitConfig(ema_decay=0.0).validate()  # 0: off, the default
    with pytest.raises(ValueError, match="ema decay"):
        WeightAverage(_Tiny(), 0.0)


def test_the_average_leaves_the_training_path_alone_and_is_what_is_kept(small_run):
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_fit import fit_stream_gru

    ds = load_dataset(small_run / "dataset.npz")
    tiny = dict(epochs=2, hidden=4, segment=80, tbptt=40, warmup=10, batch=16)
    plain, h_plain = fit_stream_gru(ds, StreamFitConfig(**tiny), log=lambda s: None)
    avg, h_avg = fit_stream_gru(ds, StreamFitConfig(**tiny, ema_decay=0.9), log=lambda s: None)
    # validating the average swaps the weights out and back: the same losses, step for step
    assert h_avg.loss == h_plain.loss
    # the kept weights are the average's, not the trained ones the plain run kept
    assert not torch.equal(avg.head.weight, plain.head.weight)
