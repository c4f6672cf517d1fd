"""What people look at: pictures of a calibration and its camera described for a person.

Pure numpy/OpenCV over arrays (no FastAPI, no database), like `app.calib`, which it draws from.
"""
