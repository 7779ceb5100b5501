"""Geometry: SO(3) tools, the frames and conventions, the gauge, quadric (ellipsoid) fits."""
