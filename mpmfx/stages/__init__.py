"""mpmfx.stages: one orchestration module per stage, run in this order by `runner`.

`STAGES` is the one list of stage names (the CLI's choices, the runner's order); importing
this package imports no stage.
"""

STAGES = ("voxelise", "simulate", "surface", "export", "render")
