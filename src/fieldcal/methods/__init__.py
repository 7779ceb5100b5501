"""Calibration methods, one module each, every one a ``fit(stats, **options) -> Calibration``.

- :mod:`.greedy` — the seed paper's greedy GLS algorithm (Miranda & Ferreira, Sec. 4-5).
- :mod:`.ellipsoid` — per-sensor ellipsoid fits and dot-product alignment (CK-Explorer).
- :mod:`.mle` — joint maximum likelihood with a closed-form start and uncertainty (default).
"""
