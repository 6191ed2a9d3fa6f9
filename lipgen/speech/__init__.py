"""Lip sync from speech: audio and text -> phones -> visemes -> activations -> mode coefficients."""
