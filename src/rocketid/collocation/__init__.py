"""Collocation stage: Radau points, meshes, the flat variable layout and the linear maps."""

from .radau import differentiation_matrix, element_nodes, lagrange_basis, radau_points
from .transcription import (Mesh, Transcription, VariableLayout, graded_mesh, transcribe,
                            uniform_mesh)

__all__ = ["radau_points", "element_nodes", "lagrange_basis", "differentiation_matrix",
           "Mesh", "VariableLayout", "Transcription", "transcribe", "uniform_mesh", "graded_mesh"]
