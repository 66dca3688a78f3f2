"""Indoor twins: a room scene file (TOML) per scene, read by :mod:`.reader`; the paper's two labs ship here."""
