"""py_trees behaviours and the trees that compose skills (built in a later issue)."""
