"""Bodies on the host, in numpy: meshes, springs and masses (topology), materials, strings, hair and soft bodies, and the stiffness analysis of a body (modes)."""
