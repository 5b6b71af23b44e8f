"""Robot description formats: safe XML, URDF, xacro, and the Pinocchio models built from them."""
