"""The streaming GRU's segment sampler and its class weights (train/stream_gru_segments.py): the default
draws what it drew before, ``onset_segments`` puts the onset inside the segment, ``class_mix = "sampled"``
weighs the classes of the drawn steps. Arrays only (no training)."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError


def _labels() -> np.ndarray:
    lab = np.zeros((40, 300), np.int64)
    for i in range(30):  # 30 fault flights, onsets spread over the flight; 10 healthy
        lab[i, 20 + 9 * i:] = 1 + i % 4
    return lab


def test_default_draws_the_random_numbers_of_before():
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_segments import draw_segments, first_fault

    cfg = StreamFitConfig(segment=100, warmup=10)
    onset = first_fault(_labels())
    start, mid = draw_segments(np.random.default_rng(3), 300, onset, cfg)
    # the sampler of before (train/stream_gru_fit.py up to 89a6b5e), written out
    rng = np.random.default_rng(3)
    m = rng.random(40) >= cfg.zero_start
    old = np.where(m, rng.integers(0, 300 - 100 + 1, size=40), 0)
    assert np.array_equal(start, old) and np.array_equal(mid, m & (old > 0))


def test_onset_segments_put_the_first_fault_step_inside_after_the_warmup():
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_segments import draw_segments, first_fault

    lab = _labels()
    onset = first_fault(lab)
    assert onset[0] == 20 and onset[35] == -1
    cfg = StreamFitConfig(segment=100, warmup=10, zero_start=0.0, onset_segments=1.0)
    start, mid = draw_segments(np.random.default_rng(0), 300, onset, cfg)
    fault = onset >= 0
    off = onset[fault] - start[fault]
    clipped = (start[fault] == 0) | (start[fault] == 200)
    assert ((off >= 10) & (off < 100) | clipped).all() and (~clipped).sum() >= 10  # not vacuous: most onsets lie away from the ends
    assert (off[clipped & (start[fault] == 0)] < 100).all()  # clipped at take-off: the onset still inside
    # healthy flights keep the uniform draw; a start at 0 is a take-off start (h = 0, no warm-up)
    assert np.array_equal(mid, start > 0)


def test_loss_mask_spares_only_the_warmup_of_mid_flight_segments():
    from quadfdi.train.stream_gru_segments import loss_mask

    mask = loss_mask(np.array([0, 7]), np.array([False, True]), 20, 5, 100)
    assert mask[0].all() and not mask[1, :5].any() and mask[1, 5:].all()


def test_start_span_any_reaches_the_flight_end_and_masks_past_it():
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_segments import draw_segments, loss_mask, segment_columns

    cfg = StreamFitConfig(segment=100, warmup=10, zero_start=0.0, start_span="any")
    start, mid = draw_segments(np.random.default_rng(1), 300, np.full(4000, -1), cfg)
    assert start.min() == 0 and start.max() == 289  # any sample that leaves the 10 warm-up steps
    mask = loss_mask(start, mid, 100, 10, 300)
    cols = segment_columns(start, 100, 300)
    assert cols.max() == 299 and (cols[mask] == (start[:, None] + np.arange(100))[mask]).all()
    assert not mask[start == 289, 11:].any() and mask[start == 289, 10].all()  # one loss step: the last sample
    # every sample past the first segment lies in about as many segments as any other (uniform starts)
    cover = np.bincount(cols[mask], minlength=300)[100:]
    assert cover.min() > 0.85 * cover.max()
    fit = StreamFitConfig(segment=100, warmup=10, zero_start=0.0)
    start_fit, _ = draw_segments(np.random.default_rng(1), 300, np.full(4000, -1), fit)
    assert start_fit.max() == 200  # the default: a whole segment fits


def test_sampled_class_weights_balance_the_drawn_steps():
    from quadfdi.train.data import class_weights
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_segments import sampled_class_weights

    lab = _labels()
    # whole flights from take-off: every step drawn once per draw, so the weights of every step
    whole = StreamFitConfig(segment=300, zero_start=1.0, class_mix="sampled")
    assert sampled_class_weights(lab, whole, 5) == pytest.approx(class_weights(lab.ravel(), 5), rel=1e-6)
    # 100-step segments, half from take-off: the early (healthy) steps are over-drawn, so Healthy's
    # weight falls and the faults' rise against the every-step weights
    part = StreamFitConfig(segment=100, warmup=10, class_mix="sampled")
    w, w_all = sampled_class_weights(lab, part, 5), class_weights(lab.ravel(), 5)
    assert w[0] < w_all[0] and (w[1:] > w_all[1:]).all()


def test_bad_segment_settings_are_refused():
    from quadfdi.train.config import StreamFitConfig

    with pytest.raises(QuadfdiError, match="class_mix"):
        StreamFitConfig(class_mix="windows").validate()
    with pytest.raises(QuadfdiError, match="start_span"):
        StreamFitConfig(start_span="end").validate()
    with pytest.raises(QuadfdiError, match="onset_segments"):
        StreamFitConfig(onset_segments=1.5).validate()
    with pytest.raises(QuadfdiError, match="choose one"):
        StreamFitConfig(class_mix="sampled", onset_weight=2.0).validate()
