"""What checks the user's input and writes the user's files, and runs nothing: the allowed
ranges (limits), the checks that name a field, its value and what is allowed (validation), the
strict reading of a scene file's TOML tables (scene_file), and atomic file writes (files)."""
