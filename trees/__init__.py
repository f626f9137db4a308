"""py_trees behaviours and the trees that compose skills."""
