"""LIGGGHTS 3.8 adapter: scene -> input script + data file, run, parse into the result tables."""
