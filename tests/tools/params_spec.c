/* Prints the params spec of every job kind as JSON ({"kind": {"field":
 * {"type", "default", "minimum", ...}}}), for the check of api/openapi.yaml's
 * per-kind params schemas against them (params_spec_check.py). */
#include <stdio.h>
#include <stdlib.h>

#include "jobs/kind.h"
#include "kinds.h"

int main(void)
{
    cJSON *o = cJSON_CreateObject();
    for (size_t i = 0; o && i < vx_kind_count(); i++) {
        const vx_kind *k = vx_kind_at(i);
        cJSON *d = vx_spec_describe(k->spec);
        if (!d || !cJSON_AddItemToObject(o, k->name, d)) {
            cJSON_Delete(d);
            cJSON_Delete(o);
            o = NULL;
        }
    }
    char *text = o ? cJSON_Print(o) : NULL;
    if (!text) {
        fprintf(stderr, "params_spec: out of memory\n");
        return 1;
    }
    puts(text);
    free(text);
    cJSON_Delete(o);
    return 0;
}
