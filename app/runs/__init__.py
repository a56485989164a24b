"""Runs: every mapping session and mission, recorded (app/recorder.py), stored, reviewed and replayed."""
