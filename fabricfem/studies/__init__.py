"""Studies that reproduce the papers' figures (hours, not tests): sleeve, unit cell, fabric link."""
