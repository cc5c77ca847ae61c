"""The DVC stage scripts: one short function each, run by stages._runner (see its docstring)."""
