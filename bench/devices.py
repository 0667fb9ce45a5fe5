"""Peak FP32 rates of known GPUs, to state a bench row's throughput as a share of the device (issue 32).

Keyed by a substring of ``GL_RENDERER`` (the first that matches, in order: the specific names before the
general ones). The figures are the vendors' datasheet FP32 rates (non-tensor, boost clock) in TFLOP/s, halved
to multiply-adds (one FMA = 2 FLOP): NVIDIA H100 Tensor Core GPU datasheet (H100 SXM 67 TFLOP/s, H100 NVL 60,
H100 PCIe 51), NVIDIA H200 datasheet (H200 SXM 67, H200 NVL 60), NVIDIA A100 datasheet (19.5). The H100 lent
to this project reports ``NVIDIA H100 80GB HBM3/PCIe/SSE2`` (HBM3: the SXM5 board; "/PCIe/SSE2" is the
driver's generic suffix, not the board). A CPU rasterizer (llvmpipe) or an unknown GPU has no entry: its
share stays blank.
"""

from __future__ import annotations

__all__ = ["FP32_TFLOPS", "fp32_tmac_per_s"]

#: (GL_RENDERER substring, FP32 TFLOP/s), first match wins.
FP32_TFLOPS: tuple[tuple[str, float], ...] = (
    ("H100 PCIe", 51.2),
    ("H100 NVL", 60.0),
    ("H100", 66.9),
    ("H200 NVL", 60.0),
    ("H200", 66.9),
    ("A100", 19.5),
)


def fp32_tmac_per_s(gl_renderer: str) -> float | None:
    """The device's peak FP32 multiply-add rate in TMAC/s (TFLOP/s / 2), or ``None`` when unknown."""
    for key, tflops in FP32_TFLOPS:
        if key in gl_renderer:
            return tflops / 2.0
    return None
