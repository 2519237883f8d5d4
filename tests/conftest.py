import os
import sys

# make `tests/gof.py` importable as `gof` from every test module
sys.path.insert(0, os.path.dirname(__file__))
