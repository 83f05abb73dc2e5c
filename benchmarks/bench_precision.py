"""How far a bf16 critic's Q lies from the float32 one's, with its output layer in bf16 or in float32.

A freshly initialised critic of the paper's size (3 x 256 ReLU, FetchPush's 32 inputs) on one batch
of 256 normalised inputs, its output bias set to 0 and to -15 (a trained Fetch critic's Q lies in
[-50, 0]), run under bf16 autocast with every layer bf16 and with the output layer float32
(:class:`hersd.learners.base.FullPrecisionLinear`, what precision=bf16 builds), each against float32.

Usage: python benchmarks/bench_precision.py (a second; docs/LEARNERS.md, "Precision").
"""

from __future__ import annotations

import torch

from hersd.learners.base import FullPrecisionLinear, mlp

INPUTS, BATCH, OFFSETS = 32, 256, (0.0, -15.0)


def q_errors(offset: float) -> dict[str, torch.Tensor]:
    """abs(Q_bf16 - Q_fp32) (BATCH, 1) of the two bf16 variants of a critic whose Q is about ``offset``."""
    torch.manual_seed(0)
    inputs = torch.randn(BATCH, INPUTS).clamp(-5.0, 5.0)
    plain = mlp(INPUTS, 1, 3, 256)
    with torch.no_grad():
        plain[-1].bias.fill_(offset)
    float_output = mlp(INPUTS, 1, 3, 256, FullPrecisionLinear)
    float_output.load_state_dict(plain.state_dict())
    with torch.no_grad():
        q = plain(inputs)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return {"every layer bf16": (plain(inputs).float() - q).abs(),
                    "output layer float32": (float_output(inputs) - q).abs()}


def main() -> None:
    for offset in OFFSETS:
        for label, error in q_errors(offset).items():
            print(f"Q near {offset:+5.0f}, {label:<21} mean abs error {error.mean():.1e}, max {error.max():.1e}")


if __name__ == "__main__":
    main()
