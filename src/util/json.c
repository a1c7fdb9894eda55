/* Exact JSON numbers (json.h). */
#include "util/json.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Writes d with the fewest digits, 15 to 17, that strtod reads back as
 * exactly d into buf; returns that count (15 for what cJSON's own 15
 * digits already print exactly, integers and non-finite numbers too). */
static int exact_digits(double d, char buf[32])
{
    int p = 15;
    if (!isfinite(d)) return p;
    for (; p < 17; p++) {
        snprintf(buf, 32, "%1.*g", p, d);
        if (strtod(buf, NULL) == d) return p;
    }
    snprintf(buf, 32, "%1.17g", d);
    return p;
}

/* Whether j or a value inside it is a number 15 digits would change. */
static int any_inexact(const cJSON *j)
{
    char buf[32];
    if (cJSON_IsNumber(j) && exact_digits(j->valuedouble, buf) > 15) return 1;
    for (const cJSON *c = j->child; c; c = c->next)
        if (any_inexact(c)) return 1;
    return 0;
}

/* Turns each number of the (copied) tree that 15 digits would change into
 * raw text of the digits that do not. Returns 0, or -1 out of memory. */
static int make_exact(cJSON *j)
{
    char buf[32];
    if (cJSON_IsNumber(j) && exact_digits(j->valuedouble, buf) > 15) {
        size_t n = strlen(buf) + 1;
        char *raw = cJSON_malloc(n);
        if (!raw) return -1;
        memcpy(raw, buf, n);
        j->type = cJSON_Raw | (j->type & cJSON_StringIsConst);
        j->valuestring = raw;
    }
    for (cJSON *c = j->child; c; c = c->next)
        if (make_exact(c) != 0) return -1;
    return 0;
}

char *vx_json_print(const cJSON *doc, int formatted)
{
    if (!doc) return NULL;
    if (!any_inexact(doc)) return formatted ? cJSON_Print(doc) : cJSON_PrintUnformatted(doc);
    cJSON *copy = cJSON_Duplicate(doc, 1);
    if (!copy) return NULL;
    char *text = NULL;
    if (make_exact(copy) == 0) text = formatted ? cJSON_Print(copy) : cJSON_PrintUnformatted(copy);
    cJSON_Delete(copy);
    return text;
}
