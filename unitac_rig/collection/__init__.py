"""Collection: the force-terminated press, the session plan (sweeps, rotations, resume) and extraction."""
