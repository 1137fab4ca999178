"""A simple non-neural baseline on the same windows: logistic regression on window statistics.

It shows what the neural models add over plain window statistics. For each window
(W samples x C channels) the telemetry is first normalised per channel with the mean and
standard deviation of the TRAINING windows (all their samples), then three features per
channel are taken: the mean, the least-squares slope against the window's normalised time
t in [0, 1] (t_i = i / (W - 1), the same time axis as the Neural ODE's path) and the standard
deviation -- 3 C features. A ``StandardScaler`` and a multinomial
``LogisticRegression(class_weight="balanced")`` follow, all in one scikit-learn ``Pipeline``.

``fit_baseline(windows, y, seed)`` returns the fitted pipeline; ``predict_proba_baseline``
always returns (n, K) probabilities in label order (K = ``n_classes`` given to the fit: the data's
class count, the paper's 4 by default), with zeros for a class the model never saw in training.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from quadfdi.core.contracts import N_CLASSES

MAX_ITER = 2000


def _check_windows(windows: Any) -> np.ndarray:
    x = np.asarray(windows)
    if x.ndim != 3:
        raise ValueError(f"windows must have shape (n, W, C), found {x.shape}")
    if x.shape[0] == 0 or x.shape[1] < 2:
        raise ValueError(f"windows must hold at least one window of at least 2 samples, found {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("windows contain NaN or inf")
    return x.astype(np.float64, copy=False)


def window_features(x: np.ndarray) -> np.ndarray:
    """(n, W, C) normalised windows -> (n, 3 C) features [mean_c..., slope_c..., std_c...]."""
    n, w, c = x.shape
    t = np.linspace(0.0, 1.0, w)
    tc = t - t.mean()
    mean = x.mean(axis=1)
    slope = np.einsum("w,nwc->nc", tc, x) / float(tc @ tc)  # least squares: cov(t, x) / var(t)
    std = x.std(axis=1)
    return np.concatenate([mean, slope, std], axis=1)


class WindowFeatures(TransformerMixin, BaseEstimator):
    """Channel normalisation fitted on the training windows, then ``window_features``."""

    def fit(self, X, y=None):
        x = _check_windows(X)
        flat = x.reshape(-1, x.shape[2])
        self.mean_ = flat.mean(axis=0)
        std = flat.std(axis=0)
        self.std_ = np.where(std > 1e-12, std, 1.0)  # a constant channel is only centred
        self.n_channels_ = x.shape[2]
        return self

    def transform(self, X):
        x = _check_windows(X)
        if x.shape[2] != self.n_channels_:
            raise ValueError(f"windows have {x.shape[2]} channels, the baseline was fitted on {self.n_channels_}")
        return window_features((x - self.mean_) / self.std_)


def fit_baseline(windows_train: Any, y_train: Any, seed: int = 0, n_classes: int = N_CLASSES) -> Pipeline:
    """Fit the baseline on (n, W, C) training windows and their labels in 0..n_classes-1."""
    x = _check_windows(windows_train)
    y = np.asarray(y_train)
    if y.shape != (x.shape[0],):
        raise ValueError(f"y_train must have shape ({x.shape[0]},), found {y.shape}")
    y = y.astype(np.int64)
    if y.min() < 0 or y.max() >= n_classes:
        raise ValueError(f"y_train labels must be in 0..{n_classes - 1}, found range [{y.min()}, {y.max()}]")
    if len(np.unique(y)) < 2:
        raise ValueError(f"the baseline needs at least two classes in training, found only label {y[0]}")
    model = Pipeline(
        [
            ("features", WindowFeatures()),
            ("scale", StandardScaler()),
            (
                "clf",
                LogisticRegression(class_weight="balanced", max_iter=MAX_ITER, random_state=int(seed)),
            ),
        ]
    )
    model.fit(x, y)
    model.quadfdi_n_classes = int(n_classes)  # the width of predict_proba_baseline's output
    return model


def predict_proba_baseline(model: Pipeline, windows: Any) -> np.ndarray:
    """(n, K) class probabilities in label order (0 for a class absent from training)."""
    x = _check_windows(windows)
    p = model.predict_proba(x)
    out = np.zeros((x.shape[0], getattr(model, "quadfdi_n_classes", N_CLASSES)), dtype=np.float64)
    out[:, np.asarray(model.classes_, dtype=np.int64)] = p
    return out
