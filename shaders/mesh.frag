#version 430
// One RG32F target: r = linear depth (object units), g = face index (gl_PrimitiveID of the
// indexed GL_TRIANGLES draw == row of mesh.faces).  Float ids are exact below 2^24 faces;
// the renderer refuses larger meshes.  Background keeps the clear value (0, -1).
in float v_depth;
layout(location = 0) out vec2 depth_and_face;

void main() {
    depth_and_face = vec2(v_depth, float(gl_PrimitiveID));
}
