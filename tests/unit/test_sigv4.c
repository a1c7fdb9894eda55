/* libcurl's AWS Signature V4 (CURLOPT_AWS_SIGV4, what the s3:// blob store
 * signs with) against AWS's published test suite vectors: the Authorization
 * header curl sends is captured by a listener on a free local port and
 * compared with the suite's expected value. Each vector fixes the time with
 * an X-Amz-Date header, which curl signs instead of its clock. Then the
 * requests the s3 backend makes (x-amz-content-sha256: UNSIGNED-PAYLOAD, a
 * sorted encoded query, a streamed PUT body) against a signature computed
 * here from the specification with nettle, as S3 would check it. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <curl/curl.h>
#include <nettle/hmac.h>
#include <nettle/sha2.h>
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
typedef struct body {
    const char *p;
    size_t n, at;
} body;

static size_t read_body(char *buf, size_t size, size_t nitems, void *ud)
{
    body *b = ud;
    size_t k = size * nitems < b->n - b->at ? size * nitems : b->n - b->at;
    memcpy(buf, b->p + b->at, k);
    b->at += k;
    return k;
}

static void request(const char *method, const char *target, const char *service, const char *hdr,
                    const char *upload, char *auth, size_t n)
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
    if (hdr) hd = curl_slist_append(hd, hdr);
    char sigv4[64];
    snprintf(sigv4, sizeof sigv4, "aws:amz:us-east-1:%s", service);
    curl_easy_setopt(h, CURLOPT_URL, url);
    curl_easy_setopt(h, CURLOPT_CONNECT_TO, to);
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, hd);
    curl_easy_setopt(h, CURLOPT_AWS_SIGV4, sigv4);
    curl_easy_setopt(h, CURLOPT_USERPWD, "AKIDEXAMPLE:wJalrXUtnFEMI/K7MDENG+bPxRfiCYEXAMPLEKEY");
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(h, CURLOPT_TIMEOUT, 20L);
    body up = {upload, upload ? strlen(upload) : 0, 0};
    if (upload) { /* streamed, as the backend sends files */
        curl_easy_setopt(h, CURLOPT_UPLOAD, 1L);
        curl_easy_setopt(h, CURLOPT_READFUNCTION, read_body);
        curl_easy_setopt(h, CURLOPT_READDATA, &up);
        curl_easy_setopt(h, CURLOPT_INFILESIZE_LARGE, (curl_off_t)up.n);
    } else if (strcmp(method, "GET")) {
        /* No body and no Content-Type, as in the suite's POSTs. */
        curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, method);
    }
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

static void signed_request(const char *method, const char *target, char *auth, size_t n)
{
    request(method, target, "service", NULL, NULL, auth, n);
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

static void hex(const uint8_t *d, size_t n, char *out)
{
    for (size_t i = 0; i < n; i++)
        sprintf(out + 2 * i, "%02x", d[i]);
}

static void hmac(const uint8_t *key, size_t kn, const char *msg, uint8_t out[32])
{
    struct hmac_sha256_ctx c;
    hmac_sha256_set_key(&c, kn, key);
    hmac_sha256_update(&c, strlen(msg), (const uint8_t *)msg);
    hmac_sha256_digest(&c, 32, out);
}

/* The Authorization header for an S3 request whose only signed headers are
 * host, x-amz-content-sha256 (UNSIGNED-PAYLOAD) and x-amz-date, computed
 * from the Signature V4 specification. */
static void expected_s3(const char *method, const char *path, const char *query, char *out,
                        size_t n)
{
    char creq[2048], sts[512], h[65];
    snprintf(creq, sizeof creq,
             "%s\n%s\n%s\nhost:example.amazonaws.com\nx-amz-content-sha256:UNSIGNED-PAYLOAD\n"
             "x-amz-date:20150830T123600Z\n\nhost;x-amz-content-sha256;x-amz-date\n"
             "UNSIGNED-PAYLOAD",
             method, path, query);
    uint8_t d[32];
    struct sha256_ctx c;
    sha256_init(&c);
    sha256_update(&c, strlen(creq), (const uint8_t *)creq);
    sha256_digest(&c, 32, d);
    hex(d, 32, h);
    snprintf(sts, sizeof sts,
             "AWS4-HMAC-SHA256\n20150830T123600Z\n20150830/us-east-1/s3/aws4_request\n%s", h);
    const char *secret = "AWS4wJalrXUtnFEMI/K7MDENG+bPxRfiCYEXAMPLEKEY";
    uint8_t k1[32], k2[32], k3[32], k4[32], sig[32];
    hmac((const uint8_t *)secret, strlen(secret), "20150830", k1);
    hmac(k1, 32, "us-east-1", k2);
    hmac(k2, 32, "s3", k3);
    hmac(k3, 32, "aws4_request", k4);
    hmac(k4, 32, sts, sig);
    hex(sig, 32, h);
    snprintf(out, n,
             "AWS4-HMAC-SHA256 Credential=AKIDEXAMPLE/20150830/us-east-1/s3/aws4_request, "
             "SignedHeaders=host;x-amz-content-sha256;x-amz-date, Signature=%s",
             h);
}

/* The backend's requests: curl signs the given payload hash header, not a
 * hash of the (streamed) body, and the query as given. */
static void test_s3_requests(void **state)
{
    (void)state;
    const char *payload = "x-amz-content-sha256: UNSIGNED-PAYLOAD";
    char auth[1024], want[1024];
    request("GET", "/bucket?delimiter=%2F&list-type=2&prefix=voxeld%2Fmeshes%2F", "s3", payload,
            NULL, auth, sizeof auth);
    expected_s3("GET", "/bucket", "delimiter=%2F&list-type=2&prefix=voxeld%2Fmeshes%2F", want,
                sizeof want);
    assert_string_equal(auth, want);
    request("PUT", "/bucket/voxeld/meshes/a.obj?partNumber=2&uploadId=x%2By", "s3", payload,
            "v 0 0 0\nv 1 0 0\n", auth, sizeof auth);
    expected_s3("PUT", "/bucket/voxeld/meshes/a.obj", "partNumber=2&uploadId=x%2By", want,
                sizeof want);
    assert_string_equal(auth, want);
    /* The check can fail: another path signs differently. */
    expected_s3("PUT", "/bucket/voxeld/meshes/b.obj", "partNumber=2&uploadId=x%2By", want,
                sizeof want);
    assert_string_not_equal(auth, want);
}

int main(void)
{
    curl_global_init(CURL_GLOBAL_DEFAULT);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_get_vanilla), cmocka_unit_test(test_post_vanilla),
        cmocka_unit_test(test_get_query),   cmocka_unit_test(test_post_query),
        cmocka_unit_test(test_s3_requests),
    };
    int rc = cmocka_run_group_tests(tests, NULL, NULL);
    curl_global_cleanup();
    return rc;
}
