"""The synthetic visuo-tactile sensor: objects pressed into an elastic gel, shaded and captured.

Modules: objects (height fields), gel (contact), optics (illumination, vignetting, noise),
scene (effects and renderer), motion (sequence motion), plan (entries), truth (npz files),
simulate (workers and the recordings folder). See docs/simulator.md.
"""
