"""A toy bomgraph method plugin (see ``mapper.py``)."""
