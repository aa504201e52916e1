"""Experiments: the one place that knows the agents and the baselines together (Fig. 2 and the
learned controller against the references)."""
