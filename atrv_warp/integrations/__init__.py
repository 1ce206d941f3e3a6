"""Bridges to other tools, one job per module. The simulator and the task know nothing about them.

- :mod:`.recorder`: :class:`~.recorder.RerunRecorder`, the simulator's worlds to a Rerun recording;
  :mod:`.blueprint`: the layout every recording opens with (a 3D view first, plots in tabs);
- :mod:`.viewer`: :class:`~.viewer.ServedViewer`, Rerun's web viewer as a process on 127.0.0.1;
  :mod:`.browser`: that viewer in headless Chromium (screenshots, tests);
- :mod:`.rerun_logger`: :class:`~.rerun_logger.RerunLogger`, training scalars into a Rerun recording;
- :mod:`.ros`: a ROS 2 node (:mod:`.ros.bag`: its MCAP bags; :mod:`.ros.frames`: its frame tree;
  :mod:`.ros.markers`: the world as markers);
- :mod:`.gymnasium`: Gymnasium and vector-env adapters.
"""
