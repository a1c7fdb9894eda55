#version 450 core
// Preview (src/preview/render.c): positions arrive already normalised (bbox
// centre at the origin, bounding sphere radius 1), so there is no model matrix.
layout(location = 0) in vec3 a_pos;
layout(location = 0) uniform mat4 u_view;
layout(location = 1) uniform mat4 u_proj;
out vec3 v_view_pos;

void main()
{
    vec4 vp = u_view * vec4(a_pos, 1.0);
    v_view_pos = vp.xyz;
    gl_Position = u_proj * vp;
}
