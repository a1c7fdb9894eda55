/* The one path-length constant: every buffer that holds a file-system path
 * (data dir, mesh, blob and result paths, temp names) has VX_PATH_MAX bytes;
 * a data dir is at most VX_PATH_MAX / 2 - 1 bytes, so that the names the
 * store makes under it always fit. */
#ifndef VX_PATH_H
#define VX_PATH_H

#define VX_PATH_MAX 4096

#endif
