"""The shipped tasks, one module each: :mod:`.reach` (the reference), :mod:`.nav` (terrain, obstacles, a scanner),
:mod:`.nav_deploy` (nav as a robot drives it). Each declares ``TASK``, a :class:`~atrv_warp.task.definition.Task`;
:mod:`atrv_warp.task.registry` registers them."""
