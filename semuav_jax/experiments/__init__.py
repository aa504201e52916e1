"""Experiments: the one place that knows the agents and the baselines together (Fig. 2 and its figures, the
learned controller against the references)."""
