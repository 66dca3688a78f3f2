"""The core layer: dataset ids, the per-cell schema, the ``Dataset`` view, the grid, errors and the on-disk layout.

Everything here is plain data and small helpers; every other layer of ``dtradar_data`` builds on it.
"""
