"""Collision detection: broad phases, candidate buffers, narrow phase and the detector interface."""
