"""Development-time scripts, run as ``python scripts/NAME.py``.

A package only so that the tests import them as ``scripts.NAME`` (the suite
puts the repository's root on ``sys.path``), and mypy names them alike.
"""
