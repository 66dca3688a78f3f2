"""Building datasets: the resumable scene -> ray tracing -> Parquet pipeline (:mod:`.builder`), coverage maps
(:mod:`.coverage`) and synthetic tables for tests without a ray tracer (:mod:`.synthetic`)."""
