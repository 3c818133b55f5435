"""Analyses of traced bundles: spot statistics, ray fans (and later distortion, illumination, PSFs)."""
