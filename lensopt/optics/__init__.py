"""The differentiable core: surfaces, intersections, bending, paraxial optics, sampling, trace, aiming.

Pure batched torch functions over tensors; no printing, no global dtype/device (DESIGN.md rules 1–3).
"""
