/* libcurl's AWS Signature V4 (CURLOPT_AWS_SIGV4, what the s3:// blob store
 * signs with) against AWS's published test suite vectors: the Authorization
 * header curl sends is captured by a listener on a free local port and
 * compared with the suite's expected value. Each vector fixes the time with
 * an X-Amz-Date header, which curl signs instead of its clock. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <curl/curl.h>
#include <netinet/in.h>
#include <pthread.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

/* One request head, read by a thread that answers 200 and closes. */
typedef struct listener {
    int fd;
    int port;
    char head[8192];
} listener;

static void *serve_one(void *ud)
{
    listener *l = ud;
    int c = accept(l->fd, NULL, NULL);
    if (c < 0) return NULL;
    size_t n = 0;
    while (n + 1 < sizeof l->head) {
        ssize_t k = read(c, l->head + n, sizeof l->head - 1 - n);
        if (k <= 0) break;
        n += (size_t)k;
        l->head[n] = 0;
        if (strstr(l->head, "\r\n\r\n")) break;
    }
    const char *ok = "HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n";
    ssize_t w = write(c, ok, strlen(ok));
    (void)w;
    close(c);
    return NULL;
}

static void listen_any(listener *l)
{
    memset(l, 0, sizeof *l);
    l->fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    assert_true(l->fd >= 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    assert_int_equal(bind(l->fd, (struct sockaddr *)&a, sizeof a), 0);
    assert_int_equal(listen(l->fd, 1), 0);
    socklen_t len = sizeof a;
    assert_int_equal(getsockname(l->fd, (struct sockaddr *)&a, &len), 0);
    l->port = ntohs(a.sin_port);
}

/* The value of header name in the captured head, into out. */
static int header_of(const char *head, const char *name, char *out, size_t n)
{
    size_t ln = strlen(name);
    for (const char *p = strstr(head, "\r\n"); p; p = strstr(p + 2, "\r\n")) {
        if (strncasecmp(p + 2, name, ln) == 0 && p[2 + ln] == ':') {
            const char *v = p + 3 + ln;
            while (*v == ' ')
                v++;
            size_t vl = strcspn(v, "\r\n");
            if (vl >= n) return -1;
            memcpy(out, v, vl);
            out[vl] = 0;
            return 0;
        }
    }
    return -1;
}

/* Sends method target to example.amazonaws.com (connected to the
 * listener), signed for us-east-1 / "service" with the suite's key pair at
 * the suite's time; returns the Authorization header it carried. */
static void signed_request(const char *method, const char *target, char *auth, size_t n)
{
    listener l;
    listen_any(&l);
    pthread_t t;
    assert_int_equal(pthread_create(&t, NULL, serve_one, &l), 0);
    char url[256], connect_to[128];
    snprintf(url, sizeof url, "http://example.amazonaws.com%s", target);
    snprintf(connect_to, sizeof connect_to, "example.amazonaws.com:80:127.0.0.1:%d", l.port);
    CURL *h = curl_easy_init();
    assert_non_null(h);
    struct curl_slist *to = curl_slist_append(NULL, connect_to);
    /* The suite's requests carry only Host and X-Amz-Date (curl's own
     * Accept is not signed; a header named here would be, even empty). */
    struct curl_slist *hd = curl_slist_append(NULL, "X-Amz-Date: 20150830T123600Z");
    curl_easy_setopt(h, CURLOPT_URL, url);
    curl_easy_setopt(h, CURLOPT_CONNECT_TO, to);
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, hd);
    curl_easy_setopt(h, CURLOPT_AWS_SIGV4, "aws:amz:us-east-1:service");
    curl_easy_setopt(h, CURLOPT_USERPWD, "AKIDEXAMPLE:wJalrXUtnFEMI/K7MDENG+bPxRfiCYEXAMPLEKEY");
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(h, CURLOPT_TIMEOUT, 20L);
    /* No body and no Content-Type, as in the suite's POSTs. */
    if (strcmp(method, "GET")) curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, method);
    CURLcode rc = curl_easy_perform(h);
    long status = 0;
    curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    curl_easy_cleanup(h);
    curl_slist_free_all(hd);
    curl_slist_free_all(to);
    pthread_join(t, NULL);
    close(l.fd);
    assert_int_equal(rc, CURLE_OK);
    assert_int_equal(status, 200);
    char host[128];
    assert_int_equal(header_of(l.head, "Host", host, sizeof host), 0);
    assert_string_equal(host, "example.amazonaws.com");
    char date[64];
    assert_int_equal(header_of(l.head, "X-Amz-Date", date, sizeof date), 0);
    assert_string_equal(date, "20150830T123600Z");
    assert_int_equal(header_of(l.head, "Authorization", auth, n), 0);
}

#define SUITE_PREFIX                                                                               \
    "AWS4-HMAC-SHA256 Credential=AKIDEXAMPLE/20150830/us-east-1/service/aws4_request, "            \
    "SignedHeaders=host;x-amz-date, Signature="

/* get-vanilla: GET / */
static void test_get_vanilla(void **state)
{
    (void)state;
    char auth[1024];
    signed_request("GET", "/", auth, sizeof auth);
    assert_string_equal(auth, SUITE_PREFIX
                        "5fa00fa31553b73ebf1942676e86291e8372ff2a2260956d9b8aae1d763fbf31");
}

/* post-vanilla: POST / with an empty body */
static void test_post_vanilla(void **state)
{
    (void)state;
    char auth[1024];
    signed_request("POST", "/", auth, sizeof auth);
    assert_string_equal(auth, SUITE_PREFIX
                        "5da7c1a2acd57cee7505fc6676e4e544621c30862966e37dddb68e92efbe5d6b");
}

/* get-vanilla-empty-query-key: GET /?Param1=value1 (the query is signed) */
static void test_get_query(void **state)
{
    (void)state;
    char auth[1024];
    signed_request("GET", "/?Param1=value1", auth, sizeof auth);
    assert_string_equal(auth, SUITE_PREFIX
                        "a67d582fa61cc504c4bae71f336f98b97f1ea3c7a6bfe1b6e45aec72011b9aeb");
}

/* post-vanilla-query: POST /?Param1=value1 */
static void test_post_query(void **state)
{
    (void)state;
    char auth[1024];
    signed_request("POST", "/?Param1=value1", auth, sizeof auth);
    assert_string_equal(auth, SUITE_PREFIX
                        "28038455d6de14eafc1f9222cf5aa6f1a96197d7deb8263271d420d138af7f11");
}

int main(void)
{
    curl_global_init(CURL_GLOBAL_DEFAULT);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_get_vanilla),
        cmocka_unit_test(test_post_vanilla),
        cmocka_unit_test(test_get_query),
        cmocka_unit_test(test_post_query),
    };
    int rc = cmocka_run_group_tests(tests, NULL, NULL);
    curl_global_cleanup();
    return rc;
}
