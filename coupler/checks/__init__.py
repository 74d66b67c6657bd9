"""Comparisons of a run's result with known solutions (the scene's ``[check]``)."""
