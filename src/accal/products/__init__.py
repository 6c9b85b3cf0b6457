"""Views of accal's output products (the tables a run leaves in its output directory)."""
