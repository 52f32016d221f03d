/* mini_json.c - see mini_json.h. Enough JSON for vectors.json: objects, arrays, strings
 * without escapes other than \" and \\, numbers, true/false/null. */
#include "mini_json.h"

#include <stdlib.h>
#include <string.h>

static int parse_value(const char *js, size_t len, size_t *pos, mj_tok *t, int max, int *n);

static void skip_ws(const char *js, size_t len, size_t *pos)
{
    while (*pos < len && strchr(" \t\r\n", js[*pos]) && js[*pos])
        (*pos)++;
}

static int new_tok(mj_tok *t, int max, int *n, mj_type type, int start)
{
    if (*n >= max)
        return -1;
    t[*n].type = type;
    t[*n].start = start;
    t[*n].end = start;
    t[*n].size = 0;
    return (*n)++;
}

static int parse_string(const char *js, size_t len, size_t *pos, mj_tok *t, int max, int *n)
{
    size_t p = *pos + 1;
    int i = new_tok(t, max, n, MJ_STR, (int)p);
    if (i < 0)
        return -1;
    while (p < len && js[p] != '"') {
        if (js[p] == '\\')
            p++;
        p++;
    }
    if (p >= len)
        return -1;
    t[i].end = (int)p;
    *pos = p + 1;
    return i;
}

static int parse_value(const char *js, size_t len, size_t *pos, mj_tok *t, int max, int *n)
{
    skip_ws(js, len, pos);
    if (*pos >= len)
        return -1;
    char c = js[*pos];
    if (c == '"')
        return parse_string(js, len, pos, t, max, n);
    if (c == '{' || c == '[') {
        int i = new_tok(t, max, n, c == '{' ? MJ_OBJ : MJ_ARR, (int)*pos);
        if (i < 0)
            return -1;
        char close = c == '{' ? '}' : ']';
        (*pos)++;
        skip_ws(js, len, pos);
        if (*pos < len && js[*pos] == close) {
            (*pos)++;
            t[i].end = (int)*pos;
            return i;
        }
        for (;;) {
            if (c == '{') {
                skip_ws(js, len, pos);
                if (*pos >= len || js[*pos] != '"' || parse_string(js, len, pos, t, max, n) < 0)
                    return -1;
                skip_ws(js, len, pos);
                if (*pos >= len || js[*pos] != ':')
                    return -1;
                (*pos)++;
            }
            if (parse_value(js, len, pos, t, max, n) < 0)
                return -1;
            t[i].size++;
            skip_ws(js, len, pos);
            if (*pos < len && js[*pos] == ',') {
                (*pos)++;
                continue;
            }
            if (*pos < len && js[*pos] == close) {
                (*pos)++;
                t[i].end = (int)*pos;
                return i;
            }
            return -1;
        }
    }
    int i = new_tok(t, max, n, MJ_PRIM, (int)*pos);
    if (i < 0)
        return -1;
    while (*pos < len && !strchr(",]} \t\r\n", js[*pos]))
        (*pos)++;
    t[i].end = (int)*pos;
    return i;
}

int mj_parse(const char *js, size_t len, mj_tok *t, int max)
{
    size_t pos = 0;
    int n = 0;
    if (parse_value(js, len, &pos, t, max, &n) < 0)
        return -1;
    return n;
}

int mj_skip(const mj_tok *t, int i)
{
    int kids = t[i].size;
    int j = i + 1;
    for (int k = 0; k < kids; k++) {
        if (t[i].type == MJ_OBJ)
            j++; /* key */
        j = mj_skip(t, j);
    }
    return j;
}

int mj_eq(const char *js, const mj_tok *t, int i, const char *s)
{
    size_t l = strlen(s);
    return (size_t)(t[i].end - t[i].start) == l && !memcmp(js + t[i].start, s, l);
}

int mj_get(const char *js, const mj_tok *t, int obj, const char *key)
{
    int j = obj + 1;
    for (int k = 0; k < t[obj].size; k++) {
        if (mj_eq(js, t, j, key))
            return j + 1;
        j = mj_skip(t, j + 1);
    }
    return -1;
}

int mj_item(const mj_tok *t, int arr, int k)
{
    int j = arr + 1;
    for (int m = 0; m < k; m++)
        j = mj_skip(t, j);
    return j;
}

uint64_t mj_u64(const char *js, const mj_tok *t, int i) { return strtoull(js + t[i].start, NULL, 10); }

static int hexval(char c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

long mj_hex(const char *js, const mj_tok *t, int i, uint8_t *out, size_t cap)
{
    int n = t[i].end - t[i].start;
    if (n % 2 || (size_t)(n / 2) > cap)
        return -1;
    for (int k = 0; k < n / 2; k++) {
        int hi = hexval(js[t[i].start + 2 * k]), lo = hexval(js[t[i].start + 2 * k + 1]);
        if (hi < 0 || lo < 0)
            return -1;
        out[k] = (uint8_t)(hi << 4 | lo);
    }
    return n / 2;
}
