"""pytest plugin of hapticsdk (fixtures for plugin authors)."""
