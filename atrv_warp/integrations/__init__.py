"""Bridges to other tools: :mod:`.rerun` (recordings and the web viewer), :mod:`.ros` (a ROS 2
node), :mod:`.gymnasium` (Gymnasium and vector-env adapters). The simulator and the task know
nothing about them."""
