"""Tasks shipped with chronogym."""
