"""Storage: the crash-safe HDF5 session recorder, the reader, and dataset summaries."""
