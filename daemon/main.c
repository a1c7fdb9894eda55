#include <stdio.h>
int main(void) { puts("voxeld " VX_VERSION); return 0; }
