"""YADE 2023.02a adapter: scene -> YADE Python script, run with `yade -n -x -j1`, parse into the result tables."""
