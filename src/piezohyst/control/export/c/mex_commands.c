/* A template: the dollar-brace names are filled in at export. The MEX gateways' own
 * commands, after their state: NAME('reset') and NAME('version'). */
/* 1 when the call was a command (done), 0 when it was not. */
static int run_command(int nrhs, mxArray *plhs[], const mxArray *prhs[])
{
    char command[16];
    if (!(nrhs == 1 && mxIsChar(prhs[0]))) {
        return 0;
    }
    if (mxGetString(prhs[0], command, sizeof command) != 0) {
        mexErrMsgIdAndTxt("${name}:command", "the commands are 'reset' and 'version'");
    }
    if (strcmp(command, "reset") == 0) {
        ${prefix}_init(&state);
        return 1;
    }
    if (strcmp(command, "version") == 0) {
        plhs[0] = mxCreateString("${version}");
        return 1;
    }
    mexErrMsgIdAndTxt("${name}:command", "unknown command '%s' (reset, version)", command);
    return 1;
}
