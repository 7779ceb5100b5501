"""Pose statistics (seed paper Eq. 5, 7) and the noise that goes with them."""
