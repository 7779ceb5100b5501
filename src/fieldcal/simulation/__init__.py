"""Simulated sessions with a known truth: still poses (Table 1) and continuous logs."""
