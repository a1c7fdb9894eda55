/* daemon/config.c: every flag can be set from a VOXELD_* variable named
 * from the flag table; the file < the environment < the flags. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config.h"

static int load(vx_config *c, int argc, char **argv)
{
    return vx_config_load(c, argc, argv);
}

/* Writes n bytes of text (n 0: up to its NUL) to path, a mkstemp template
 * the first time (its XXXXXX still there), the file it named after. */
static void config_file(char *path, const char *text, size_t n)
{
    int fd = strstr(path, "XXXXXX") ? mkstemp(path) : open(path, O_WRONLY | O_TRUNC);
    assert_true(fd >= 0);
    if (!n) n = strlen(text);
    assert_int_equal(write(fd, text, n), (ssize_t)n);
    close(fd);
}

static void test_env_sets_every_kind(void **state)
{
    setenv("VOXELD_LISTEN", "0.0.0.0:9000", 1);
    setenv("VOXELD_MAX_UPLOAD_BYTES", "2M", 1);
    setenv("VOXELD_JOB_TIMEOUT", "12.5", 1);
    setenv("VOXELD_HTTP_THREADS", "3", 1);
    setenv("VOXELD_GL_DEBUG", "no", 1);
    setenv("VOXELD_LOG_LEVEL", "debug", 1);
    setenv("VOXELD_MAX_EVENT_STREAMS", "7", 1);
    setenv("VOXELD_REQUIRE_GPU", "yes", 1);
    vx_config c;
    char *argv[] = {"voxeld", NULL};
    assert_int_equal(load(&c, 1, argv), 0);
    assert_string_equal(c.listen, "0.0.0.0:9000");
    assert_int_equal(c.max_upload_bytes, 2u << 20);
    assert_true(c.job_timeout_s == 12.5);
    assert_int_equal(c.http_threads, 3);
    assert_int_equal(c.gl_debug, 0);
    assert_int_equal(c.log_level, VX_LOG_DEBUG);
    assert_int_equal(c.max_event_streams, 7);
    assert_int_equal(c.require_gpu, 1);
    /* A flag wins over its variable. */
    char *argv2[] = {"voxeld", "--listen",      "127.0.0.1:0", "--max-event-streams",
                     "9",      "--require-gpu", "no",          NULL};
    assert_int_equal(load(&c, 7, argv2), 0);
    assert_string_equal(c.listen, "127.0.0.1:0");
    assert_int_equal(c.max_event_streams, 9);
    assert_int_equal(c.require_gpu, 0);
    assert_int_equal(c.max_upload_bytes, 2u << 20);
    unsetenv("VOXELD_LISTEN");
    unsetenv("VOXELD_MAX_UPLOAD_BYTES");
    unsetenv("VOXELD_JOB_TIMEOUT");
    unsetenv("VOXELD_HTTP_THREADS");
    unsetenv("VOXELD_GL_DEBUG");
    unsetenv("VOXELD_LOG_LEVEL");
    unsetenv("VOXELD_MAX_EVENT_STREAMS");
    unsetenv("VOXELD_REQUIRE_GPU");
    assert_int_equal(load(&c, 1, argv), 0);
    assert_string_equal(c.listen, "127.0.0.1:8080");
    assert_int_equal(c.require_gpu, 0); /* off by default */
    assert_int_equal(c.max_event_streams, 64);
    assert_int_equal(c.max_waits, 64);
}

static void test_env_bad_value(void **state)
{
    setenv("VOXELD_MAX_CONNECTIONS", "lots", 1);
    vx_config c;
    char *argv[] = {"voxeld", NULL};
    assert_int_equal(load(&c, 1, argv), -1);
    unsetenv("VOXELD_MAX_CONNECTIONS");
}

static void test_env_over_file(void **state)
{
    char path[] = "/tmp/vx-config-XXXXXX";
    config_file(path, "workers = 5\nmax-queued-jobs = 11\n", 0);
    setenv("VOXELD_CONFIG", path, 1);
    setenv("VOXELD_WORKERS", "6", 1);
    vx_config c;
    char *argv[] = {"voxeld", NULL};
    assert_int_equal(load(&c, 1, argv), 0);
    assert_int_equal(c.workers, 6);          /* the variable over the file */
    assert_int_equal(c.max_queued_jobs, 11); /* the file, from VOXELD_CONFIG */
    char *argv2[] = {"voxeld", "--workers", "4", NULL};
    assert_int_equal(load(&c, 3, argv2), 0);
    assert_int_equal(c.workers, 4);
    unsetenv("VOXELD_CONFIG");
    unsetenv("VOXELD_WORKERS");
    unlink(path);
}

/* Values that must be refused rather than run: a config that is a
 * directory or named "", times past 1e9 s (a library takes some as 32-bit:
 * 4294967297 s of connection-timeout closed connections after 1 s), URI
 * and head limits no request fits. A '#' inside a value is the value's. */
static void test_refused_and_comments(void **state)
{
    (void)state;
    vx_config c;
    char dir[] = "/tmp/vx-config-dir-XXXXXX";
    assert_non_null(mkdtemp(dir));
    char *a1[] = {"voxeld", "--config", dir, NULL};
    assert_int_equal(load(&c, 3, a1), -1);
    char *a2[] = {"voxeld", "--config", "", NULL};
    assert_int_equal(load(&c, 3, a2), -1);
    rmdir(dir);
    const char *bad[][2] = {{"--connection-timeout", "4294967297"},
                            {"--job-timeout", "99999999999999999999"},
                            {"--event-keepalive", "1e10"},
                            {"--max-uri-bytes", "0"},
                            {"--max-uri-bytes", "255"},
                            {"--max-header-bytes", "0"},
                            {"--max-header-bytes", "1023"},
                            /* past what libmicrohttpd's connection memory holds */
                            {"--max-uri-bytes", "131073"},
                            {"--max-header-bytes", "1G"},
                            /* under the GL thread's pings, about a second apart */
                            {"--gl-stall-timeout", "1.5"},
                            {"--gl-stall-timeout", "0.001"},
                            /* seconds are a decimal number, as documented */
                            {"--job-timeout", "0x10"},
                            {"--job-timeout", "+5"},
                            {"--job-timeout", " 5"},
                            {"--job-timeout", "inf"},
                            {"--job-timeout", "5 "},
                            /* brackets hold an IPv6 address only */
                            {"--listen", "[127.0.0.1]:8080"},
                            {"--listen", "[]:8080"},
                            {"--listen", "[localhost]:8080"},
                            {"--listen", "::1:8080"},
                            {"--listen", "[::1]8080"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char *av[] = {"voxeld", (char *)bad[i][0], (char *)bad[i][1], NULL};
        assert_int_equal(load(&c, 3, av), -1);
    }
    char *ok[] = {"voxeld", "--connection-timeout", "1e9", "--max-uri-bytes", "256", NULL};
    assert_int_equal(load(&c, 5, ok), 0);
    assert_true(c.connection_timeout_s == 1e9);
    char *ok2[] = {"voxeld", "--max-uri-bytes",    "128K", "--max-header-bytes",
                   "128K",   "--gl-stall-timeout", "2",    NULL};
    assert_int_equal(load(&c, 7, ok2), 0);
    assert_true(c.max_header_bytes == 128 << 10 && c.gl_stall_timeout_s == 2);
    char *off[] = {"voxeld", "--gl-stall-timeout", "0", NULL};
    assert_int_equal(load(&c, 3, off), 0);
    static const char *const listens[] = {"[::1]:0", "[::]:8080", "[fe80::1%lo]:9", ":0",
                                          "127.0.0.1:65535"};
    for (size_t i = 0; i < sizeof listens / sizeof *listens; i++) {
        char *av[] = {"voxeld", "--listen", (char *)listens[i], NULL};
        assert_int_equal(load(&c, 3, av), 0);
    }
    char path[] = "/tmp/vx-config-XXXXXX";
    char *a3[] = {"voxeld", "--config", path, NULL};
    config_file(path, "# a comment\nreplica-name = node#1  # the first\nworkers = 3#\n", 0);
    assert_int_equal(load(&c, 3, a3), -1); /* "3#" is no count */
    config_file(path, "# a comment\nreplica-name = node#1  # the first\nworkers = 3 #\n", 0);
    assert_int_equal(load(&c, 3, a3), 0);
    assert_string_equal(c.replica_name, "node#1");
    assert_int_equal(c.workers, 3);
    /* A NUL in a line is an error (it cut the value short); a comment of
     * 3000 bytes is one line (a 2 KiB buffer read its tail as another). */
    static const char nul[] = "replica-name = ab\0cd\n";
    config_file(path, nul, sizeof nul - 1);
    assert_int_equal(load(&c, 3, a3), -1);
    char text[3200] = "# ";
    memset(text + 2, 'x', 3000);
    snprintf(text + 3002, sizeof text - 3002, "\nreplica-name = %0100d\n", 0);
    config_file(path, text, 0);
    assert_int_equal(load(&c, 3, a3), 0);
    assert_int_equal(strlen(c.replica_name), 100);
    /* a UTF-8 byte order mark before the first key is no part of it */
    config_file(path, "\xef\xbb\xbfmax-queued-jobs = 7\n", 0);
    assert_int_equal(load(&c, 3, a3), 0);
    assert_int_equal(c.max_queued_jobs, 7);
    unlink(path);
    /* max-parse-memory: its default follows max-upload-bytes; any value
     * given is kept, 2^64 - 1 too (it was the mark of "not given") */
    char *p1[] = {"voxeld", "--max-upload-bytes", "1M", NULL};
    assert_int_equal(load(&c, 3, p1), 0);
    assert_true(c.max_parse_memory == (8ull << 20) + (256ull << 20));
    char *p2[] = {"voxeld", "--max-parse-memory", "18446744073709551615", NULL};
    assert_int_equal(load(&c, 3, p2), 0);
    assert_true(c.max_parse_memory == UINT64_MAX);
    char *p3[] = {"voxeld", "--max-parse-memory", "0", NULL};
    assert_int_equal(load(&c, 3, p3), 0);
    assert_true(c.max_parse_memory == 0);
    char *ts[] = {"voxeld", "--job-timeout", "2.5e1", NULL};
    assert_int_equal(load(&c, 3, ts), 0);
    assert_true(c.job_timeout_s == 25);
}

/* An empty data dir (data-dir = in a file, VOXELD_DATA_DIR=$UNSET) is a bad
 * option, as an empty listen is: it ran on and died at mkdir "" (exit 1).
 * A size is digits and a unit: a blank or a sign before it is no size
 * (" -1" read as 2^64 - 1), nor is a unit given twice. */
static void test_empty_dir_and_signed_sizes(void **state)
{
    (void)state;
    vx_config c;
    const char *bad[][2] = {{"--data-dir", ""},
                            {"--max-upload-bytes", " -1"},
                            {"--max-upload-bytes", "-1"},
                            {"--max-upload-bytes", "+5"},
                            {"--max-upload-bytes", " 5"},
                            {"--max-upload-bytes", "\t5"},
                            {"--max-upload-bytes", "5BB"},
                            {"--max-upload-bytes", "5iB"},
                            {"--min-free-disk", " -64M"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char *av[] = {"voxeld", (char *)bad[i][0], (char *)bad[i][1], NULL};
        assert_int_equal(load(&c, 3, av), -1);
    }
    setenv("VOXELD_DATA_DIR", "", 1);
    char *argv[] = {"voxeld", NULL};
    assert_int_equal(load(&c, 1, argv), -1);
    unsetenv("VOXELD_DATA_DIR");
    char *ok[] = {"voxeld", "--max-upload-bytes", "5KiB", "--min-free-disk", "2TB", NULL};
    assert_int_equal(load(&c, 5, ok), 0);
    assert_int_equal(c.max_upload_bytes, 5u << 10);
    assert_true(c.min_free_disk == 2ull << 40);
}

/* A token file that cannot be read is named in the message: "token file:
 * cannot open the file" left the operator to guess which. */
/* load() with what it writes to stderr into out (n bytes, NUL-ended). */
static int load_said(vx_config *c, int argc, char **argv, char *out, size_t n)
{
    char errpath[] = "/tmp/vx-config-err-XXXXXX";
    int fd = mkstemp(errpath);
    assert_true(fd >= 0);
    int saved = dup(2);
    dup2(fd, 2);
    int rc = load(c, argc, argv);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    memset(out, 0, n);
    assert_true(pread(fd, out, n - 1, 0) >= 0);
    close(fd);
    unlink(errpath);
    return rc;
}

static void test_token_file_named(void **state)
{
    (void)state;
    vx_config c;
    char *argv[] = {"voxeld", "--token-file", "/nonexistent/vx-token", NULL};
    char buf[1024];
    assert_int_equal(load_said(&c, 3, argv, buf, sizeof buf), -1);
    assert_non_null(strstr(buf, "token file /nonexistent/vx-token: "));
    /* a token of 511 bytes is taken whole; one of 512 was cut to 511 and
     * the whole one refused (401) */
    char path[] = "/tmp/vx-token-XXXXXX", tok[601];
    for (size_t len = 511; len <= 600; len += 89) {
        memset(tok, 'k', len);
        tok[len] = '\n';
        config_file(path, tok, len + 1);
        char *av[] = {"voxeld", "--token-file", path, NULL};
        int rc = load_said(&c, 3, av, buf, sizeof buf);
        if (len == 511) {
            assert_int_equal(rc, 0);
            assert_int_equal(strlen(c.token), 511);
        } else {
            assert_int_equal(rc, -1);
            assert_non_null(strstr(buf, "a token of 600 bytes, over the 511 taken"));
        }
    }
    unlink(path);
}

/* A VOXELD_ variable that names no option is warned about on stderr and
 * ignored; the clients' own (VOXELD_URL, ...) are not. */
static void test_unknown_env_warned(void **state)
{
    (void)state;
    setenv("VOXELD_WORKER", "3", 1); /* WORKERS misspelled */
    setenv("VOXELD_URL", "http://x", 1);
    vx_config c;
    char *argv[] = {"voxeld", NULL};
    char buf[1024];
    int rc = load_said(&c, 1, argv, buf, sizeof buf);
    unsetenv("VOXELD_WORKER");
    unsetenv("VOXELD_URL");
    assert_int_equal(rc, 0);
    assert_non_null(strstr(buf, "VOXELD_WORKER names no option"));
    assert_null(strstr(buf, "VOXELD_URL"));
}

/* The forms an operator writes: size suffixes in any case (64kib was
 * refused while 64kB was taken), yes/no options as systemd's booleans
 * (ON was refused while 1 was taken), an empty VOXELD_CONFIG refused as
 * --config '' is (it was ignored), a value over its longest said so and
 * not echoed whole (a 100 KB line was). */
static void test_operator_forms(void **state)
{
    (void)state;
    vx_config c;
    const char *sizes[] = {"64kib", "64KIB", "64kb", "64Kb", "64K", "65536B"};
    for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
        char *av[] = {"voxeld", "--max-upload-bytes", (char *)sizes[i], NULL};
        assert_int_equal(load(&c, 3, av), 0);
        assert_int_equal(c.max_upload_bytes, 64u << 10);
    }
    const char *on[] = {"ON", "Yes", "TRUE", "on", "1"}, *off[] = {"OFF", "No", "False", "0"};
    for (size_t i = 0; i < sizeof on / sizeof on[0]; i++) {
        char *av[] = {"voxeld", "--reuse-port", (char *)on[i], NULL};
        assert_int_equal(load(&c, 3, av), 0);
        assert_int_equal(c.reuse_port, 1);
    }
    for (size_t i = 0; i < sizeof off / sizeof off[0]; i++) {
        char *av[] = {"voxeld", "--reuse-port", (char *)off[i], NULL};
        assert_int_equal(load(&c, 3, av), 0);
        assert_int_equal(c.reuse_port, 0);
    }
    char *maybe[] = {"voxeld", "--reuse-port", "maybe", NULL};
    assert_int_equal(load(&c, 3, maybe), -1);
    char buf[2048];
    setenv("VOXELD_CONFIG", "", 1);
    char *none[] = {"voxeld", NULL};
    int rc = load_said(&c, 1, none, buf, sizeof buf);
    unsetenv("VOXELD_CONFIG");
    assert_int_equal(rc, -1);
    assert_non_null(strstr(buf, "VOXELD_CONFIG is empty"));
    char path[] = "/tmp/vx-config-forms-XXXXXX"; /* ... but --config given wins */
    config_file(path, "workers = 3\n", 0);
    setenv("VOXELD_CONFIG", "", 1);
    char *given[] = {"voxeld", "--config", path, NULL};
    rc = load(&c, 3, given);
    unsetenv("VOXELD_CONFIG");
    unlink(path);
    assert_int_equal(rc, 0);
    assert_int_equal(c.workers, 3);
    char *bytes[] = {"voxeld", "--max-upload-bytes", "64B", NULL};
    assert_int_equal(load(&c, 3, bytes), 0);
    assert_int_equal(c.max_upload_bytes, 64);
    char part[700]; /* two list values over the list's longest together: said so */
    memset(part, 'o', sizeof part - 1);
    memcpy(part, "http://", 7);
    part[sizeof part - 1] = 0;
    /* an origin of another shape than a browser's never matches one */
    static const char *const no_origin[] = {"a.example",
                                            "http://a.example/",
                                            "http://a.example:99999",
                                            "http://a.example:0",
                                            "http://",
                                            "http://a.example, b.example",
                                            "http://a b",
                                            "https://a.example:443",
                                            "http://a.example:80",
                                            "http://a.example:080"};
    for (size_t i = 0; i < sizeof no_origin / sizeof *no_origin; i++) {
        char *av[] = {"voxeld", "--cors-origin", (char *)no_origin[i], NULL};
        assert_int_equal(load_said(&c, 3, av, buf, sizeof buf), -1);
        assert_non_null(strstr(buf, "cors-origin takes origins"));
    }
    char *origins[] = {
        "voxeld",        "--cors-origin",     "http://b.example:8000,\thttps://c.example:80,null",
        "--cors-origin", "http://[::1]:5173", NULL};
    assert_int_equal(load(&c, 5, origins), 0);
    char *two[] = {"voxeld", "--cors-origin", part, "--cors-origin", part, NULL};
    assert_int_equal(load_said(&c, 5, two, buf, sizeof buf), -1);
    assert_non_null(strstr(buf, "(want at most 1023 bytes in all)"));
    char name[1001];
    memset(name, 'a', 1000);
    name[1000] = 0;
    char *lng[] = {"voxeld", "--replica-name", name, NULL};
    assert_int_equal(load_said(&c, 3, lng, buf, sizeof buf), -1);
    assert_non_null(strstr(buf, "(want at most 127 bytes)"));
    assert_true(strlen(buf) < 400);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_env_sets_every_kind),
        cmocka_unit_test(test_env_bad_value),
        cmocka_unit_test(test_env_over_file),
        cmocka_unit_test(test_refused_and_comments),
        cmocka_unit_test(test_unknown_env_warned),
        cmocka_unit_test(test_empty_dir_and_signed_sizes),
        cmocka_unit_test(test_token_file_named),
        cmocka_unit_test(test_operator_forms),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
