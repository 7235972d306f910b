"""The documentation site, opened in a browser (``make docs``)."""
