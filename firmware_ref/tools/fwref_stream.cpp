// tools/fwref_stream.cpp -- scope: the streaming runtime (fwref/stream.hpp) on a recorded stream
// (a contract: outside tools drive it, docs/firmware.md "Streaming"):
//
//   fwref_stream --weights <weights.bin> --model cnode|gru|sgru [--int8] --in <stream.bin | -> [--out <lines.txt>]
//                [--manifest <manifest.json>] [--timings <seconds.f64>] [--vehicle <record.bin>]
//   fwref_stream --weights <weights.bin> --model scnode --step-weights <scnode_weights[_i8].bin> [--int8] --in ...
//   fwref_stream --weights <weights.bin> --info [--model cnode|gru|sgru]
//
// The alarm policy is the bound model's: its row of the record's alarm.models (one policy per network),
// else the record's single policy (a record written before the table, or a model it omits).
// --model sgru: the streaming GRU, one step per usable sample (fwref/gru_step.hpp); --weights is then
// the export's sgru_weights.bin (formats/sgru_weights.py: the sgru sections and a copy of weights.bin's
// on-board record). --model scnode: the streaming CNODE, one RK4 step per usable sample (fwref/cnode_step.hpp),
// its weights the export's scnode_weights.bin / scnode_weights_i8.bin (--int8; fwref/scnode_file.hpp, no flight),
// the record and the alarm policy weights.bin's (the record's single policy: alarm.models has no scnode row).
// cnode / gru with a motor head (sections cnode_motor / gru_motor in weights.bin)
// run infer_motor: the motor columns below are then filled.
//
// stream.bin (docs/formats.md "Stream file", written by `quadfdi stream-file`): a header (magic,
// version, channel names, sample period, profile, cell count), then samples (f64 time, f32 values
// in the header's channel order), read one sample at a time from a regular file, a FIFO or stdin
// ("-"); a device, folder or socket is refused (tools/stream_io.hpp). The header is bounded and checked
// (tools/stream_file.hpp): channels and profile the on-board record's, the period finite, positive and
// the record's within fwref/read_limits.hpp's tolerance. A regular file must hold whole samples, checked
// before anything is written. Every --in is opened and its header checked before the first sample runs.
// A channel the flight lacks (version 2's carried flag 0) only the masked profile accepts
// (Stream::set_carried: its minimum always, and a cell count while it carries V_b).
// --in may be given several times: the flights run in sequence through one Stream, reset() between
// them (each flight's lines start with its "# fwref_stream flight=<i>" comment).
// The vehicle record (a reference profile, flightlog-ref; fwref/vehicle_record.hpp): a stream file of version 3
// or 4 carries its own, loaded into the Stream at the flight's reset (set_vehicle); --vehicle <record.bin> (a record
// file, formats/vehicle_record_bin.py, checked to be for the model's profile) is the record of every flight whose
// stream carries none, and is refused for a stream that carries one. Neither: no reference (the reference
// channels at their fills, avail_reference 0). The flight's comment line says vehicle=stream|file|none.
// Output (stdout, or --out through a temp file renamed at the end): '#' comment lines, then one line per
// reported stride, at most one per sample (fwref/stream.hpp: the strides inside a timestamp gap are
// counted, not reported):  index t status logit_1..K proba_1..K vote active raised cleared cls motor wmotor
// (status decided | skipped | nohover; logits %.9g (float32 round trip), proba %.17g, NaN when
// not decided; cls/motor the alarm's class and reported motor (core/alarm.py's rules 4-5), -1 while no
// alarm or, for motor, without a motor head or when the alarm's class is not rotor-side (the record's
// alarm.rotor_side; a record without it: every class); wmotor this stride's motor-head argmax 0..3, -1 when not decided
// or without a head). --info prints the on-board record as key=value lines (rotor_side: the 0/1
// flags per class, or "all" for a record written before them); threshold..latch are --model's policy
// (without --model: the record's single policy), policy_from says where from (alarm.models | alarm.policy)
// and alarm_models lists the table as model:threshold,k,n,clear_m,latch;... ("none" without it).
// The last comment line per flight: "# end samples= dropped= decided= skipped= steps= hover_cmd= hover_cur=
// gap_strides= resyncs=" (dropped: refused times; gap_strides: strides that ended inside a gap; resyncs: new
// clocks taken, fwref/stream.hpp). --timings writes (samples,) float64 seconds per push (steady clock).
// Errors: one line, exit 2, no output file (a failed write included: EFBIG under `ulimit -f` removes the
// temp file); usage errors exit 1. Neither output grows in memory with the stream.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/cnode_step.hpp"
#include "fwref/onboard.hpp"
#include "fwref/scnode_file.hpp"
#include "fwref/stream.hpp"
#include "fwref/vehicle_record.hpp"
#include "host_common.hpp"
#include "host_motor.hpp"
#include "host_files.hpp"
#include "stream_file.hpp"
#include "stream_io.hpp"

namespace {

const fwref::host::Cli kCli(
    "fwref_stream",
    "usage: fwref_stream --weights <weights.bin> (--info [--model cnode|gru|sgru] | --model cnode|gru|sgru|scnode "
    "[--step-weights <scnode_weights.bin>] [--int8] --in <stream.bin|-> [--out <lines.txt>] [--manifest <manifest.json>] "
    "[--timings <seconds.f64>] [--vehicle <record.bin>])");
// The model's code in the record's alarm.models; the streaming CNODE has none (kModelNone: no row matches it,
// so it runs the record's single policy).
std::uint32_t model_code(const std::string& model) {
  return model == "cnode" ? fwref::kModelCnode : model == "gru" ? fwref::kModelGru
                                                                : model == "scnode" ? fwref::kModelNone : fwref::kModelSgru;
}

const char* model_name(std::uint32_t code) {
  return code == fwref::kModelCnode ? "cnode" : code == fwref::kModelGru ? "gru" : "sgru";
}

void print_info(const fwref::OnboardRecord& r, bool from_table) {
  const fwref::StreamParams& p = r.params;
  std::printf("profile=%s\nwindow=%d\nstride=%d\nsample_dt_s=%.9g\ncells_from_stream=%d\n",
              fwref::profile_spec(p.profile).name, p.window, p.stride, p.sample_dt_s, int(r.cells_from_stream));
  std::printf("hover_steady_samples=%d\nhover_settle_samples=%d\nhover_limits=%.9g,%.9g,%.9g\n", r.hover_steady,
              r.hover_settle, r.hover_limits[0], r.hover_limits[1], r.hover_limits[2]);
  std::printf("threshold=%.17g\nk=%d\nn=%d\nclear_m=%d\nlatch=%d\nhealthy=%d\n", p.alarm.threshold, p.alarm.k,
              p.alarm.n, p.alarm.clear_m, int(p.alarm.latch), p.alarm.healthy);
  std::string rotor = r.rotor_classes == 0 ? "all" : "";  // "all": a record without alarm.rotor_side
  for (int c = 0; c < r.rotor_classes; ++c) rotor += (c ? "," : "") + std::to_string((p.alarm.rotor_mask >> c) & 1u);
  std::printf("rotor_side=%s\npolicy_from=%s\n", rotor.c_str(), from_table ? "alarm.models" : "alarm.policy");
  std::string table = r.model_policies.empty() ? "none" : "";
  for (const fwref::OnboardRecord::ModelPolicy& m : r.model_policies) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s%s:%.17g,%d,%d,%d,%d", table.empty() ? "" : ";", model_name(m.model),
                  m.alarm.threshold, m.alarm.k, m.alarm.n, m.alarm.clear_m, int(m.alarm.latch));
    table += buf;
  }
  std::printf("alarm_models=%s\n", table.c_str());
  std::string raw, model;
  for (const std::string& s : r.raw_names) raw += (raw.empty() ? "" : ",") + s;
  for (const std::string& s : r.model_names) model += (model.empty() ? "" : ",") + s;
  std::printf("raw_channels=%s\nchannels=%s\n", raw.c_str(), model.c_str());
  std::printf("stream_bytes=%zu\n", sizeof(fwref::Stream));  // this build's capacities (fwref/config.hpp)
}

// One output line per reported stride, to the output as it comes.
class Lines final : public fwref::StrideSink {
 public:
  Lines(int classes, fwref::host::StreamOutput& out) : k_(classes), out_(out) {}
  void on_stride(const fwref::Decision& d) override {
    char buf[96];
    std::string line;
    std::snprintf(buf, sizeof buf, "%lld %.6f %s", static_cast<long long>(d.index), d.t,
                  fwref::stride_status_name(d.status));
    line += buf;
    for (int k = 0; k < k_; ++k) std::snprintf(buf, sizeof buf, " %.9g", double(d.logits[k])), line += buf;
    for (int k = 0; k < k_; ++k) std::snprintf(buf, sizeof buf, " %.17g", d.proba[k]), line += buf;
    std::snprintf(buf, sizeof buf, " %d %d %d %d %d %d %d\n", int(d.alarm.vote), int(d.alarm.active),
                  int(d.alarm.raised), int(d.alarm.cleared), d.alarm.cls, d.alarm.motor, d.motor);
    line += buf;
    add(line);
  }
  void add(const std::string& s) { out_.put(s); }
  bool failed() const { return out_.failed(); }

 private:
  int k_;
  fwref::host::StreamOutput& out_;
};

fwref::Stream g_stream;  // 143 kB with the host's defaults (--info: stream_bytes): static, not on the stack

fwref::Status run_window(void* ctx, const float* window, float* logits) {
  return static_cast<fwref::host::Model*>(ctx)->run(window, logits);
}

fwref::Status run_motor(void* ctx, const float* window, float* logits, float* motor) {
  return static_cast<fwref::host::MotorModel*>(ctx)->run(window, logits, motor);
}

// What the stream runs, bound from the weights file; lives as long as main.
struct Bound {
  std::unique_ptr<fwref::host::Model> window;
  std::unique_ptr<fwref::host::MotorModel> motor;
  fwref::GruF32 sgru_f{};
  fwref::GruI8 sgru_q{};
  fwref::GruStepState state;
  fwref::StepRunner<fwref::GruF32, fwref::GruStepState> step_f{&sgru_f, &state};
  fwref::StepRunner<fwref::GruI8, fwref::GruStepState> step_q{&sgru_q, &state};
  std::vector<unsigned char> scnode_bytes;  // the scnode weights file: its views point into it
  fwref::ScnodeFile scnode;
  fwref::ScnodeStepState scnode_state;
  fwref::StepRunner<fwref::ScnodeF32, fwref::ScnodeStepState> scnode_f{&scnode.f32, &scnode_state};
  fwref::StepRunner<fwref::ScnodeI8, fwref::ScnodeStepState> scnode_q{&scnode.i8, &scnode_state};
  fwref::StreamModel fns;
  int channels = 0, window_len = 0, classes = 0;
  bool has_motor = false;
};

// The streaming GRU's section; window 1 (one step), its channels the record's model channels.
bool bind_sgru(fwref::WeightsFile& wf, bool int8, Bound* b, std::string* error) {
  const fwref::Status s = int8 ? wf.bind_sgru(&b->sgru_q, error) : wf.bind_sgru(&b->sgru_f, error);
  if (s != fwref::Status::kOk) {
    if (s == fwref::Status::kMissingSection) *error += " (--model sgru reads the export's sgru_weights.bin)";
    return false;
  }
  const fwref::GruDims& d = int8 ? b->sgru_q.dims : b->sgru_f.dims;
  if (d.window != 1) return *error = "the sgru section has window " + std::to_string(d.window) + ", not 1", false;
  b->channels = d.channels, b->window_len = 1, b->classes = d.classes;
  b->fns.step = int8 ? &decltype(b->step_q)::step : &decltype(b->step_f)::step;
  b->fns.reset = int8 ? &decltype(b->step_q)::reset : &decltype(b->step_f)::reset;
  b->fns.ctx = int8 ? static_cast<void*>(&b->step_q) : static_cast<void*>(&b->step_f);
  return true;
}

// The streaming CNODE's weights file (--step-weights), of the precision asked for.
bool bind_scnode(const std::string& path, bool int8, Bound* b, std::string* error) {
  if (path.empty()) return *error = "--model scnode needs --step-weights <export/scnode_weights[_i8].bin>", false;
  if (!fwref::host::read_file(path, "--step-weights file", fwref::limits::kWeightsFileBytes, &b->scnode_bytes, error)) {
    return false;
  }
  const fwref::Status s = fwref::bind_scnode_file(b->scnode_bytes.data(), b->scnode_bytes.size(), &b->scnode);
  if (s != fwref::Status::kOk) return *error = path + ": not a usable streaming CNODE file (" + fwref::status_name(s) + ")", false;
  if (b->scnode.int8 != int8) {
    return *error = path + " holds the " + (b->scnode.int8 ? "int8" : "fp32") + " step: " +
                    (int8 ? "give scnode_weights_i8.bin with --int8" : "add --int8 or give scnode_weights.bin"), false;
  }
  const fwref::ScnodeDims& d = int8 ? b->scnode.i8.dims : b->scnode.f32.dims;
  b->channels = d.channels, b->window_len = 1, b->classes = d.classes;
  b->fns.step = int8 ? &decltype(b->scnode_q)::step : &decltype(b->scnode_f)::step;
  b->fns.reset = int8 ? &decltype(b->scnode_q)::reset : &decltype(b->scnode_f)::reset;
  b->fns.ctx = int8 ? static_cast<void*>(&b->scnode_q) : static_cast<void*>(&b->scnode_f);
  return true;
}

// cnode / gru, with infer_motor when weights.bin holds the net's motor head.
bool bind_stream_model(fwref::WeightsFile& wf, const std::string& model, bool int8, Bound* b, std::string* error) {
  if (model == "sgru") return bind_sgru(wf, int8, b, error);
  fwref::Status status;
  b->window = fwref::host::bind_model(wf, model, int8, &status, error);
  if (!b->window) return false;
  b->channels = b->window->channels, b->window_len = b->window->window, b->classes = b->window->classes;
  const bool head = wf.container().find(model == "cnode" ? fwref::kModelCnodeMotor : fwref::kModelGruMotor,
                                        int8 ? 2u : 1u) != nullptr;
  if (head) {
    b->motor = fwref::host::bind_motor_model(wf, model, int8, &status, error);
    if (!b->motor) return false;
    b->fns.window_motor = run_motor;
    b->fns.ctx = b->motor.get();
    b->has_motor = true;
  } else {
    b->fns.window = run_window;
    b->fns.ctx = b->window.get();
  }
  return true;
}


// The state a replay of one or more stream files shares.
struct Replay {
  const fwref::OnboardRecord& rec;
  Bound& m;
  const std::string& model;
  bool int8;
  Lines& lines;
  fwref::host::StreamOutput* seconds;  // per push, or null
  const fwref::VehicleRecord* vehicle;  // --vehicle's record, or null
  std::uint32_t cells = 0;
};

// The flight's vehicle record into the stream (after its init / reset): the stream file's own, else --vehicle's,
// else none; "stream", "file" or "none" in ``*from``.
bool load_flight_vehicle(const fwref::host::StreamHeader& h, const std::string& name, const Replay& r,
                         const char** from, std::string* error) {
  if (h.has_vehicle && r.vehicle != nullptr) {
    return *error = "stream " + name + " carries its vehicle record: --vehicle is for streams without one", false;
  }
  const fwref::VehicleRecord* v = h.has_vehicle ? &h.vehicle : r.vehicle;
  *from = h.has_vehicle ? "stream" : v != nullptr ? "file" : "none";
  if (v == nullptr) return g_stream.clear_vehicle(), true;
  if (g_stream.set_vehicle(*v) != fwref::Status::kOk) {
    return *error = std::string("profile '") + h.profile + "' reads no vehicle record", false;
  }
  return true;
}

// One stream (flight ``index`` of the replay, opened and checked): the first init()s the stream, the next
// ones reset() it (a new flight; their cell count must be the first's).
bool replay_file(fwref::host::StreamInput& in, const std::string& name, std::size_t index, Replay* r,
                 std::string* error) {
  const fwref::host::StreamHeader& h = in.header();
  fwref::StreamParams p = r->rec.params;
  p.classes = p.alarm.classes = r->m.classes;
  const std::string lacks = fwref::host::stream_lacking(h);
  const std::string refused = "stream " + name + " lacks channels profile '" + h.profile + "' cannot do without: " + lacks;
  if (index == 0) {
    const fwref::Status status = g_stream.init(p, int(h.cells), r->m.fns, h.carried);
    if (status == fwref::Status::kDimsInvalid && !lacks.empty()) return *error = refused, false;
    if (status != fwref::Status::kOk) return *error = std::string("cannot run this record: ") + fwref::status_name(status), false;
    r->cells = h.cells;
  } else if (h.cells != r->cells) {
    return *error = "stream " + name + " has " + std::to_string(h.cells) + " cells, the first stream " + std::to_string(r->cells), false;
  } else {
    g_stream.reset();
    if (g_stream.set_carried(h.carried) != fwref::Status::kOk) return *error = refused, false;
  }
  const char* vehicle = "none";
  if (!load_flight_vehicle(h, name, *r, &vehicle, error)) return false;
  char head[512];
  std::snprintf(head, sizeof head, "# fwref_stream flight=%zu source=%s model=%s precision=%s profile=%s window=%d "
                "stride=%d classes=%d motor_head=%d available=0x%X vehicle=%s\n# index t status logits[%d] proba[%d] "
                "vote active raised cleared cls motor wmotor\n", index, h.source.c_str(), r->model.c_str(),
                r->int8 ? "int8" : "fp32", h.profile.c_str(), p.window, p.stride, p.classes, int(r->m.has_motor),
                unsigned(g_stream.available()), vehicle, p.classes, p.classes);
  r->lines.add(head);
  std::vector<unsigned char> buf(h.sample_bytes());
  std::vector<float> sample(h.channels);
  long long n = 0, dropped = 0;
  for (;; ++n) {
    const int got = in.next(buf.data());
    if (got == 0) break;
    if (got < 0) return *error = "stream " + name + " ends inside sample " + std::to_string(n), false;
    const double t = fwref::host::decode_sample(buf.data(), h.channels, sample.data());
    const auto t0 = std::chrono::steady_clock::now();
    const fwref::Status s = g_stream.push(sample.data(), t, &r->lines);
    const auto t1 = std::chrono::steady_clock::now();
    if (r->seconds) {
      const double sec = std::chrono::duration<double>(t1 - t0).count();
      r->seconds->put(&sec, sizeof sec);
    }
    dropped += s != fwref::Status::kOk ? 1 : 0;
    if (r->lines.failed() || (r->seconds && r->seconds->failed())) return true;  // main reports the write
  }
  std::snprintf(head, sizeof head, "# end samples=%lld dropped=%lld decided=%lld skipped=%lld steps=%lld "
                "hover_cmd=%.9g hover_cur=%.9g gap_strides=%lld resyncs=%lld\n", n, dropped,
                static_cast<long long>(g_stream.decided()), static_cast<long long>(g_stream.skipped()),
                static_cast<long long>(g_stream.steps()), double(g_stream.hover_cmd()), double(g_stream.hover_cur()),
                static_cast<long long>(g_stream.gap_strides()), static_cast<long long>(g_stream.resyncs()));
  r->lines.add(head);
  return true;
}

}  // namespace

int main(int argc, char** argv) try {
  std::string weights, model, in, out, manifest, timings, vehicle, step_weights;
  std::vector<std::string> ins;  // --in, repeatable: flights in sequence, reset() between them
  bool int8 = false, info = false;
  const int parsed = kCli.parse(argc, argv,
                                {{"--weights", &weights}, {"--model", &model}, {"--in", &in, &ins}, {"--out", &out},
                                 {"--manifest", &manifest}, {"--timings", &timings}, {"--vehicle", &vehicle},
                                 {"--step-weights", &step_weights}},
                                {{"--int8", &int8}, {"--info", &info}});
  if (parsed >= 0) return parsed;
  if (weights.empty() || (!info && (model.empty() || ins.empty()))) return kCli.usage_error("missing arguments");
  if ((!info || !model.empty()) && model != "cnode" && model != "gru" && model != "sgru" && model != "scnode") {
    return kCli.usage_error("--model must be cnode, gru, sgru or scnode");
  }
  if (!step_weights.empty() && model != "scnode") return kCli.usage_error("--step-weights goes with --model scnode");
  std::string error;
  for (const std::string* o : {&out, &timings}) {
    for (const std::string& one : ins) {
      if (!o->empty() && !fwref::host::output_allowed(*o, {weights, one, manifest, vehicle, step_weights},
                                                      {"--weights file", "--in file", "--manifest file",
                                                       "--vehicle file", "--step-weights file"}, &error)) {
        return kCli.fail(error);
      }
    }
  }
  fwref::WeightsFile wf;
  if (!fwref::host::load_weights(weights, manifest, &wf, &error)) return kCli.fail(error);
  fwref::OnboardRecord rec;
  if (fwref::read_onboard(wf, &rec, &error) != fwref::Status::kOk) return kCli.fail(error);
  bool from_table = false;  // the bound model's policy (alarm.models), else the record's single one
  if (!model.empty()) rec.params.alarm = fwref::policy_for(rec, model_code(model), &from_table);
  if (info) return print_info(rec, from_table), 0;
  static Bound m;  // the sgru state and the bound structs: not on the stack
  if (model == "scnode" ? !bind_scnode(step_weights, int8, &m, &error) : !bind_stream_model(wf, model, int8, &m, &error)) {
    return kCli.fail(error);
  }
  if ((model != "sgru" && model != "scnode" && m.window_len != rec.params.window) || m.channels != rec.params.channels) {
    return kCli.fail("the on-board record's window/channels disagree with the " + model + " section of " + weights);
  }
  if (rec.rotor_classes != 0 && rec.rotor_classes != m.classes) {
    return kCli.fail("the on-board record's alarm.rotor_side has " + std::to_string(rec.rotor_classes) + " classes, the " +
                model + " section of " + weights + " " + std::to_string(m.classes));
  }

  static fwref::VehicleRecord vehicle_rec;
  if (!vehicle.empty() && fwref::load_vehicle_record(vehicle, rec.params.profile, &vehicle_rec, &error) != fwref::Status::kOk) {
    return kCli.fail(error);
  }
  std::vector<fwref::host::StreamInput> inputs(ins.size());
  for (std::size_t i = 0; i < ins.size(); ++i) {
    if (!inputs[i].open(ins[i], rec, &error)) return kCli.fail(error);
  }
  fwref::host::StreamOutput text, seconds;
  if (!text.open(out, &error) || (!timings.empty() && !seconds.open(timings, &error))) return kCli.fail(error);
  Lines lines(m.classes, text);
  Replay r{rec, m, model, int8, lines, timings.empty() ? nullptr : &seconds, vehicle.empty() ? nullptr : &vehicle_rec};
  for (std::size_t i = 0; i < ins.size(); ++i) {
    if (!replay_file(inputs[i], ins[i], i, &r, &error)) return kCli.fail(error);
    if (text.failed() || seconds.failed()) break;  // a failed write: reported below
  }
  if (!text.finish(&error)) return seconds.abort(), kCli.fail(error);
  if (!timings.empty() && !seconds.finish(&error)) {
    if (!out.empty()) std::remove(out.c_str());
    return kCli.fail(error);
  }
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_stream", e);
}
