"""Engine helpers. MuJoCo is the default engine; PyChrono is optional and never imported here."""
