"""Scene descriptions: frozen, validated dataclasses in SI units (materials, finger and gripper designs, force
models, the fluid, grasped objects, solver settings), presets built from them, and the discrete rod they define.
The lowest layer of the physics: it imports nothing else of the package."""
