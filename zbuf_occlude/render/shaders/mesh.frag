#version 430
// One RG32F target: r = linear depth (object units), g = face index.  Only one face of each
// group of geometrically identical faces is drawn (ModelNet duplicates many); draw_face maps
// the draw's gl_PrimitiveID to that face's row in mesh.faces, the group's lowest index.
// Float ids are exact below 2^24 faces; the renderer refuses larger meshes.  Background
// keeps the clear value (0, -1).
layout(std430, binding = DRAW_FACES) readonly buffer DrawFaces { int draw_face[]; };
in float v_depth;
layout(location = 0) out vec2 depth_and_face;

void main() {
    depth_and_face = vec2(v_depth, float(draw_face[gl_PrimitiveID]));
}
