"""Whether to trust a calibration: certificate, pose-level noise, rejected poses, verdict,
accuracy."""
