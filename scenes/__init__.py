"""The reference scenes (TOML data, installed with chaingen as chaingen.scenes)."""
