"""An exponential moving average of the streaming GRU's weights (``--ema-decay``; 0: off, the default).

After every optimiser step the shadow weights move towards the trained ones:
``shadow = d * shadow + (1 - d) * weight`` with ``d = min(decay, (1 + n) / (10 + n))`` at the n-th
update (n from 0), so the first updates follow the weights closely instead of remembering the
initialisation. Buffers (the input normalisation) are copied, not averaged. Validation and the kept
model use the shadow weights (``swapped``): the average over the last few hundred Adam steps
smooths the step-to-step noise that makes the validation curve spike from one epoch to the next
(docs/training.md "Streaming GRU").
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


class WeightAverage:
    def __init__(self, model: torch.nn.Module, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"ema decay must lie in (0, 1), found {decay}")
        self.model, self.decay, self.updates = model, decay, 0
        self.shadow = {k: v.detach().clone() for k, v in model.state_dict().items()}
        self._params = dict(model.named_parameters())

    def rate(self) -> float:
        """The decay used by the next update."""
        return min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))

    @torch.no_grad()
    def update(self) -> None:
        d = self.rate()
        for k, v in self.model.state_dict().items():
            if k in self._params and v.is_floating_point():
                self.shadow[k].mul_(d).add_(v, alpha=1.0 - d)
            else:
                self.shadow[k].copy_(v)
        self.updates += 1

    @contextmanager
    def swapped(self) -> Iterator[None]:
        """The model holds the shadow weights inside the block, its own weights again after it."""
        own = {k: v.detach().clone() for k, v in self.model.state_dict().items()}
        self.model.load_state_dict(self.shadow)
        try:
            yield
        finally:
            self.model.load_state_dict(own)
