"""Import the dataset the UniTac-NV authors published into this project's session files (see docs/import.md)."""
