"""The web pendant: its server and its static page."""
