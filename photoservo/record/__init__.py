"""Rerun recordings: the recorder, the reader, comparison and replay."""
