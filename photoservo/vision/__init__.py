"""Pixels to pose: rig, photo-model, fitness, GA, estimator, sources, synthetic scenes."""
