/* JSON text from cJSON trees with every number exact. cJSON's printer keeps
 * 15 significant digits whenever they read back within DBL_EPSILON of the
 * value, so 0.30000000000000004 came out as 0.3: a grid origin echoed,
 * journaled, compared for reuse or handed to bricks was another lattice. */
#ifndef VX_JSON_H
#define VX_JSON_H

#include <cjson/cJSON.h>

/* Like cJSON_Print (formatted) or cJSON_PrintUnformatted, but each finite
 * number is printed with the fewest digits (15 to 17) that strtod reads
 * back as exactly the same double. Free the text with cJSON_free; NULL
 * when out of memory. */
char *vx_json_print(const cJSON *doc, int formatted);

#endif
