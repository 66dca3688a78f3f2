"""Tabular RL on the lookup table: the exact solution of a twin, exact policy evaluation, tabular learners online
and from logged data, and each logged dataset's ceiling (docs: Tabular RL)."""
