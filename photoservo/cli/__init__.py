"""The command line: `photoservo VERB ...` - one thin module per verb (main.py lists them)."""
