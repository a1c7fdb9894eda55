#version 450 core
// Flat Lambert shading for the preview. The face normal comes from the
// screen-space derivatives of the view-space position: no normal attribute is
// needed, and because the screen axes fix its orientation it always faces the
// viewer, so the back faces of open meshes are lit like front faces.
in vec3 v_view_pos;
layout(location = 2) uniform vec3 u_color;
layout(location = 3) uniform float u_ambient;
layout(location = 4) uniform vec3 u_light; // view space, unit, towards the light
out vec4 o_color;

void main()
{
    vec3 c = cross(dFdx(v_view_pos), dFdy(v_view_pos));
    float len = length(c);
    // Edge-on slivers can give a zero cross product: treat them as facing us.
    vec3 n = len > 0.0 ? c / len : vec3(0.0, 0.0, 1.0);
    float lambert = max(dot(n, u_light), 0.0);
    // Alpha 1 marks geometry: the clear alpha is 0, so after the MSAA resolve
    // alpha is the pixel's coverage (render.c composites the background).
    o_color = vec4(u_color * (u_ambient + (1.0 - u_ambient) * lambert), 1.0);
}
