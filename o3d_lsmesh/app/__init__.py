"""The application over the library: operations, files, batch, command line, render, metrics, demo.

Only ``app`` imports ``app``; the library below never speaks in flags.
"""
