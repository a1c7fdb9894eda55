#version 450 core
// Depth peeling (seed 000 §2.1), src/voxel/peel.c. Positions arrive in grid
// units (normalised in double on the CPU). The ray runs along axis
// u_axes.x; the image plane is spanned by axes u_axes.y (window x) and
// u_axes.z (window y), so pixel centres are voxel centres.
layout(location = 0) in vec3 a_pos;
layout(location = 0) uniform ivec3 u_axes;
layout(location = 1) uniform vec4 u_ndc; // window x = p*u_ndc.x + u_ndc.y, y = p*u_ndc.z + u_ndc.w
invariant noperspective out float v_t; // bit-identical in every pass
invariant gl_Position;

void main()
{
    // The ray coordinate is passed through untouched (no projection maths) so
    // that every pass sees bit-identical values and a face whose vertices
    // share one coordinate interpolates to exactly that coordinate.
    v_t = a_pos[u_axes.x];
    // z = 0 with GL_DEPTH_CLAMP: nothing is clipped along the ray, crossings
    // outside the grid still count.
    gl_Position = vec4(a_pos[u_axes.y] * u_ndc.x + u_ndc.y, a_pos[u_axes.z] * u_ndc.z + u_ndc.w,
                       0.0, 1.0);
}
