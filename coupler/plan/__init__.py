"""The plan of a scene: which participants run and which fields cross between them, built by
the rules of the effects the scene asks for."""
