"""Rendering a result: POV-Ray scenes, a built-in preview renderer, and video."""
