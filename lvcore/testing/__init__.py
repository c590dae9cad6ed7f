"""Test and benchmark tooling that is not science (a real-browser driver for the app)."""
