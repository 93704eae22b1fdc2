"""The config fields by concern, one module per group (``fields.Field`` facts); ``config`` assembles them."""
