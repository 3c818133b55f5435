"""lensopt: differentiable, processing-aware lens design (see DESIGN.md for the map)."""

__version__ = "0.1.0"
