"""GratNet's GLSL sources (package data): one file per program or include, see shaders/README.md."""

from pathlib import Path

SHADER_ROOT = Path(__file__).resolve().parent
