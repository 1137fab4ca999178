"""The PyTorch adapter of the latency worker: a checkpoint, the CNODE with the solver of ``--solver``."""

from __future__ import annotations

from typing import Callable


def parse_solver(solver: str) -> tuple[str, float | int | None]:
    """'rk4-8' -> ('rk4', 8); 'dopri5-1e-3' -> ('dopri5', 0.001); 'gru' -> ('gru', None)."""
    if solver == "gru":
        return "gru", None
    method, _, value = solver.partition("-")
    try:
        if method in ("rk4", "euler", "midpoint"):
            return method, int(value)
        if method in ("dopri5", "bosh3"):
            return method, float(value)
    except ValueError:
        pass
    raise ValueError(f"solver must be gru, rk4-N, euler-N, midpoint-N, dopri5-RTOL or bosh3-RTOL; found {solver!r}")


def torch_runtime(args) -> tuple[Callable, Callable, dict]:
    """(batch-1 call, batch call, info) for a checkpoint; the CNODE's solver set from ``--solver``."""
    import torch

    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.models.networks import SolverSpec

    torch.set_num_threads(args.threads)
    model, _ = load_checkpoint(args.artifact, args.model)
    method, value = parse_solver(args.solver)
    info: dict = {"torch": torch.__version__}
    if args.model == "cnode":
        if method in ("dopri5", "bosh3"):
            # atol = rtol / 10, the solver study's convention (solverstudy.settings); jump_t on.
            model.solver = SolverSpec(method, rtol=float(value), atol=float(value) / 10, jump_t=True)
        else:
            model.solver = SolverSpec(method, steps=int(value))
        info["solver"] = {k: getattr(model.solver, k) for k in ("method", "steps", "rtol", "atol", "jump_t")}
    nfe: list[int] = []

    def call1(x):
        with torch.inference_mode():
            out = model(x)
        if args.model == "cnode":
            nfe.append(model.nfe)
        return out

    def callb(x):
        with torch.inference_mode():
            return model(x)

    info["nfe"] = nfe
    info["convert"] = torch.from_numpy
    return call1, callb, info
