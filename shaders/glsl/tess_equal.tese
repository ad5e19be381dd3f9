#version 450
// Vulkan's tessellation domain origin is the upper left, which reverses the winding the
// execution mode names (OpenGL's lower-left convention): `cw` makes the triangles of a
// counter-clockwise patch counter-clockwise, like every other method's.
// Hardware tessellation, evaluation stage with equal spacing (body: include/tess_eval.glsl).
layout(triangles, equal_spacing, cw) in;
//!include tess_eval.glsl
