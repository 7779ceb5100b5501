"""Experiment design: which pose to take next, from the Fisher information a candidate adds."""
