#version 430
// Transforms the mesh into clip space and hands linear eye-space depth to the fragment stage.
uniform mat4 view_matrix;        // world -> OpenGL eye space
uniform mat4 projection_matrix;  // eye space -> clip space
in vec3 in_position;             // world frame, object units
out float v_depth;               // linear depth along the optical axis (-z_eye), object units

void main() {
    vec4 eye_position = view_matrix * vec4(in_position, 1.0);
    v_depth = -eye_position.z;
    gl_Position = projection_matrix * eye_position;
}
