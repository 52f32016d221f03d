/* mini_json.h - a small JSON tokenizer (jsmn-style) for reading the golden vectors. */
#ifndef MINI_JSON_H
#define MINI_JSON_H

#include <stddef.h>
#include <stdint.h>

typedef enum { MJ_OBJ, MJ_ARR, MJ_STR, MJ_PRIM } mj_type;
typedef struct {
    mj_type type;
    int start, end; /* byte range in the text (strings without quotes) */
    int size;       /* children: array items, or object keys */
} mj_tok;

/* Tokenize; returns the token count or -1 on malformed input / too many tokens. */
int mj_parse(const char *js, size_t len, mj_tok *t, int max);
/* Index of the token after the subtree rooted at i. */
int mj_skip(const mj_tok *t, int i);
/* Value token of key in object obj, or -1. */
int mj_get(const char *js, const mj_tok *t, int obj, const char *key);
/* Token of item k of array arr. */
int mj_item(const mj_tok *t, int arr, int k);
uint64_t mj_u64(const char *js, const mj_tok *t, int i);
int mj_eq(const char *js, const mj_tok *t, int i, const char *s);
/* Decode a hex string token into out; returns byte count or -1. */
long mj_hex(const char *js, const mj_tok *t, int i, uint8_t *out, size_t cap);

#endif
