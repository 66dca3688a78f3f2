"""The held staging folders of the logged store: :mod:`dtradar_data.store.staging`, shared with the RT store (kept
under this name for the modules that import it from here)."""

from dtradar_data.store.staging import LOCK_SUFFIX, ORPHAN_LOCK_AGE_S, clean_stale_stages, held_stage

__all__ = ["LOCK_SUFFIX", "ORPHAN_LOCK_AGE_S", "clean_stale_stages", "held_stage"]
