"""photoservo: find, track and collect a floating creature from one photo."""

__version__ = "0.1.0"
