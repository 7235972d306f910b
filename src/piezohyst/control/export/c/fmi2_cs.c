/* FMI 2.0 Co-Simulation wrapper after an exported step (piezohyst export-fmu).
 * A template: the dollar-brace names are filled in at export. */
/* ---- FMI 2.0 Co-Simulation wrapper (piezohyst export-fmu): ${what} ---- */
#include <stdlib.h>
#include <string.h>
#include <stdio.h>
#include <stdarg.h>
#include <math.h>

#if defined(_WIN32)
#define FMI2_Export __declspec(dllexport)
#else
#define FMI2_Export __attribute__((visibility("default")))
#endif

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime,
                fmi2Terminated } fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status,
                                   fmi2String, fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define PH_GUID "{${prefix}-GUID}"
#define PH_PERIOD ${period}
#define PH_N_REAL ${n_real}

enum { PH_INSTANTIATED, PH_INITIALIZING, PH_STEPPING, PH_TERMINATED, PH_FAILED };

typedef struct {
    ${prefix}_t s;
    fmi2Real r[PH_N_REAL]; /* ${layout} */
    fmi2Real time;
    int phase;
    int logging;
    char name[64];
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
} ph_fmu_t;

static void say(ph_fmu_t *c, fmi2Status status, const char *message)
{
    if (c != NULL && c->logger != NULL && (c->logging || status >= fmi2Warning)) {
        c->logger(c->env, c->name, status, status >= fmi2Error ? "logStatusError" : "logAll",
                  "%s", message);
    }
}

static fmi2Status refuse(ph_fmu_t *c, const char *message)
{
    say(c, fmi2Error, message);
    return fmi2Error;
}

static void start(ph_fmu_t *c)
{
    ${prefix}_init(&c->s);
    ${start_outputs}
    c->time = 0.0;
    c->phase = PH_INSTANTIATED;
}

FMI2_Export const char *fmi2GetTypesPlatform(void) { return "default"; }
FMI2_Export const char *fmi2GetVersion(void) { return "2.0"; }

FMI2_Export fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                          fmi2String fmuGUID, fmi2String location,
                                          const fmi2CallbackFunctions *functions,
                                          fmi2Boolean visible, fmi2Boolean loggingOn)
{
    ph_fmu_t *c;
    (void)location;
    (void)visible;
    if (fmuType != fmi2CoSimulation || fmuGUID == NULL || strcmp(fmuGUID, PH_GUID) != 0) {
        if (functions != NULL && functions->logger != NULL) {
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                              "logStatusError", "%s",
                              "a Co-Simulation FMU with another GUID was asked for");
        }
        return NULL;
    }
    c = (ph_fmu_t *)calloc(1, sizeof(ph_fmu_t));
    if (c == NULL) {
        return NULL;
    }
    c->logger = functions != NULL ? functions->logger : NULL;
    c->env = functions != NULL ? functions->componentEnvironment : NULL;
    c->logging = loggingOn;
    strncpy(c->name, instanceName != NULL ? instanceName : "ph_fmu", sizeof c->name - 1);
    start(c);
    return c;
}

FMI2_Export void fmi2FreeInstance(fmi2Component comp) { free(comp); }

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn,
                                           size_t nCategories, const fmi2String categories[])
{
    (void)nCategories;
    (void)categories;
    if (comp == NULL) {
        return fmi2Error;
    }
    ((ph_fmu_t *)comp)->logging = loggingOn;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                                           fmi2Real tolerance, fmi2Real startTime,
                                           fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (c == NULL) {
        return fmi2Error;
    }
    if (c->phase != PH_INSTANTIATED) {
        return refuse(c, "fmi2SetupExperiment: only right after instantiation or a reset");
    }
    c->time = startTime;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component comp)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    if (c == NULL) {
        return fmi2Error;
    }
    if (c->phase != PH_INSTANTIATED) {
        return refuse(c, "fmi2EnterInitializationMode: only after instantiation or a reset");
    }
    c->phase = PH_INITIALIZING;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component comp)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    if (c == NULL) {
        return fmi2Error;
    }
    if (c->phase != PH_INITIALIZING) {
        return refuse(c, "fmi2ExitInitializationMode: not in initialization mode");
    }
    c->phase = PH_STEPPING;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component comp)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    if (c == NULL) {
        return fmi2Error;
    }
    if (c->phase != PH_STEPPING && c->phase != PH_FAILED) {
        return refuse(c, "fmi2Terminate: not stepping");
    }
    c->phase = PH_TERMINATED;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component comp)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    if (c == NULL) {
        return fmi2Error;
    }
    start(c);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[],
                                   size_t nvr, fmi2Real value[])
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) {
        return fmi2Error;
    }
    for (i = 0; i < nvr; ++i) {
        if (vr[i] >= PH_N_REAL) {
            return refuse(c, "fmi2GetReal: no variable with this value reference");
        }
        value[i] = c->r[vr[i]];
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[],
                                   size_t nvr, const fmi2Real value[])
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) {
        return fmi2Error;
    }
    if (c->phase == PH_TERMINATED) {
        return refuse(c, "fmi2SetReal: the FMU was terminated");
    }
    for (i = 0; i < nvr; ++i) {
        if (vr[i] >= PH_N_REAL || ${not_input}) {
            return refuse(c, "fmi2SetReal: only the inputs (${inputs}) can be set");
        }
        c->r[vr[i]] = value[i];
    }
    return fmi2OK;
}

static fmi2Status none(fmi2Component comp, const char *what)
{
    return refuse((ph_fmu_t *)comp, what);
}

/* the limits' counts since the last reset: ${counts_said} */
FMI2_Export fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Integer value[])
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    size_t i;
    if (c == NULL || (nvr > 0 && (vr == NULL || value == NULL))) {
        return fmi2Error;
    }
    for (i = 0; i < nvr; ++i) {
        if (vr[i] > ${last_count}) {
            return refuse(c, "fmi2GetInteger: no variable with this value reference");
        }
        value[i] = (fmi2Integer)(${count_of});
    }
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2GetBoolean: the FMU has no boolean variable");
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[],
                                     size_t nvr, fmi2String value[])
{
    (void)vr;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2GetString: the FMU has no string variable");
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Integer value[])
{
    (void)vr;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2SetInteger: the counts are outputs");
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Boolean value[])
{
    (void)vr;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2SetBoolean: the FMU has no boolean variable");
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[],
                                     size_t nvr, const fmi2String value[])
{
    (void)vr;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2SetString: the FMU has no string variable");
}

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state)
{
    (void)state;
    return none(comp, "fmi2GetFMUstate: not supported (canGetAndSetFMUstate is false)");
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state)
{
    (void)state;
    return none(comp, "fmi2SetFMUstate: not supported (canGetAndSetFMUstate is false)");
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state)
{
    (void)state;
    return none(comp, "fmi2FreeFMUstate: not supported (canGetAndSetFMUstate is false)");
}

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state,
                                                  size_t *size)
{
    (void)state;
    (void)size;
    return none(comp, "fmi2SerializedFMUstateSize: not supported");
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state,
                                             fmi2Byte serializedState[], size_t size)
{
    (void)state;
    (void)serializedState;
    (void)size;
    return none(comp, "fmi2SerializeFMUstate: not supported");
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp,
                                               const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate *state)
{
    (void)serializedState;
    (void)size;
    (void)state;
    return none(comp, "fmi2DeSerializeFMUstate: not supported");
}

FMI2_Export fmi2Status fmi2GetDirectionalDerivative(
    fmi2Component comp, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
    const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[],
    fmi2Real dvUnknown[])
{
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return none(comp, "fmi2GetDirectionalDerivative: not provided");
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp,
                                                   const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[],
                                                   const fmi2Real value[])
{
    (void)vr;
    (void)order;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2SetRealInputDerivatives: not used");
}

FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp,
                                                    const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[], fmi2Real value[])
{
    (void)vr;
    (void)order;
    (void)value;
    return nvr == 0 ? fmi2OK : none(comp, "fmi2GetRealOutputDerivatives: not provided");
}

FMI2_Export fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                                  fmi2Real communicationStepSize,
                                  fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    char message[200];
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) {
        return fmi2Error;
    }
    if (c->phase != PH_STEPPING) {
        return refuse(c, "fmi2DoStep: call fmi2ExitInitializationMode first (or the FMU was "
                         "terminated)");
    }
    if (!(fabs(communicationStepSize - PH_PERIOD) <= ${STEP_TOLERANCE} * PH_PERIOD)) {
        snprintf(message, sizeof message,
                 "fmi2DoStep: the step size %.9g s is not the compensator's sample period "
                 "%.9g s (export again with the host's rate)", communicationStepSize,
                 PH_PERIOD);
        return refuse(c, message);
    }
    ${step_statement};
    c->time = currentCommunicationPoint + communicationStepSize;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component comp)
{
    return none(comp, "fmi2CancelStep: steps are never asynchronous here");
}

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s,
                                     fmi2Status *value)
{
    (void)s;
    (void)value;
    return none(comp, "fmi2GetStatus: steps finish synchronously");
}

FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s,
                                         fmi2Real *value)
{
    ph_fmu_t *c = (ph_fmu_t *)comp;
    if (c == NULL || value == NULL || s != fmi2LastSuccessfulTime) {
        return none(comp, "fmi2GetRealStatus: only fmi2LastSuccessfulTime");
    }
    *value = c->time;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s,
                                            fmi2Integer *value)
{
    (void)s;
    (void)value;
    return none(comp, "fmi2GetIntegerStatus: not provided");
}

FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s,
                                            fmi2Boolean *value)
{
    (void)s;
    (void)value;
    return none(comp, "fmi2GetBooleanStatus: not provided");
}

FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s,
                                           fmi2String *value)
{
    (void)s;
    (void)value;
    return none(comp, "fmi2GetStringStatus: not provided");
}
