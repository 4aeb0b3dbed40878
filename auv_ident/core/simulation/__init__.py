"""Manoeuvres and what flies them: the simulator, free-run prediction, zig-zag manoeuvres and
their measures, the steering gear and the Nomoto model."""
