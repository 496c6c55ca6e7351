"""Shipped design studies (``biafc study NAME``)."""
