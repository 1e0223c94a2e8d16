"""Verification helpers that ship beside the models they check (as pbrt ships its lens
diagnostics): the checkerboard calibration check of the distortion stage
(:mod:`.checkerboard`, after Lambers, Sommerhoff & Kolb) and its sub-pixel corner refiner
(:mod:`.corner_refine`). ``tools/distortion_calibration.py`` prints the full report; the tests
run the hardest set. OpenCV (``pip install '.[test]'``) is imported only where corners are
detected or a camera is calibrated."""
