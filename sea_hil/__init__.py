"""Composition root of sea-hil: the `sea-hil` CLI and the wiring that needs plant_emulator, controller and
protocol together (offline simulation, multi-process sessions). Nothing in the three layers imports this."""
