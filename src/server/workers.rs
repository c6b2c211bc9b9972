//! The bounded pool that runs CPU work (decode, SIFT, quantize, vote) off the
//! async runtime: `workers` dedicated threads take jobs from one queue, at
//! most `queue` more jobs wait for a turn, and anything beyond is refused at
//! once so that latency cannot grow without bound. A worker that finishes a
//! job takes the next waiting one itself, with no trip through the async
//! runtime, so the workers stay busy under load even when every core is. A
//! job that panics is caught and reported as an error; the pool keeps working.
//! [`WorkerPool::close`] lets the workers finish and end before the process
//! exits (OpenCV's per-thread state must not outlive its library's teardown).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicU8, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::time::Duration;
use tokio::sync::{OwnedSemaphorePermit, Semaphore, oneshot};
use tokio::time::Instant;

/// Why a job did not produce its result.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    #[error("all workers busy and the queue full")]
    QueueFull,
    #[error("the deadline passed while waiting for a worker")]
    TimedOut,
    #[error("the job panicked: {0}")]
    Panicked(String),
}

/// A job's progress.
const WAITING: u8 = 0;
const STARTED: u8 = 1;
const ABANDONED: u8 = 2;

/// A job's claim on the pool, shared by its caller and the workers: whether
/// it was started or abandoned (whichever came first), and its admission
/// ticket, released by whichever side ends the job. An abandoned job frees
/// its place at once, though it stays in the queue until a worker skips it.
struct Place {
    progress: AtomicU8,
    ticket: Mutex<Option<OwnedSemaphorePermit>>,
}

impl Place {
    /// Move a waiting job to `to`; false when it was started or abandoned.
    fn claim(&self, to: u8) -> bool {
        self.progress
            .compare_exchange(WAITING, to, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }

    fn release(&self) {
        drop(self.ticket.lock().map(|mut t| t.take()));
    }
}

/// Runs a job and hands back what delivers its result to the caller.
type Work = Box<dyn FnOnce() -> Box<dyn FnOnce() + Send> + Send>;

/// A job in the queue.
struct Job {
    work: Work,
    place: Arc<Place>,
}

/// What a worker takes from the queue.
enum Message {
    Job(Job),
    Stop,
}

/// Worker threads still running, and a signal when one ends.
#[derive(Default)]
struct Alive {
    count: Mutex<usize>,
    ended: Condvar,
}

/// A bounded worker pool; cheap to clone (clones share the pool).
#[derive(Clone)]
pub struct WorkerPool {
    jobs: mpsc::Sender<Message>,
    alive: Arc<Alive>,
    /// One permit per job admitted (running or waiting).
    admitted: Arc<Semaphore>,
    busy: Arc<AtomicUsize>,
    workers: usize,
    queue: usize,
}

impl WorkerPool {
    /// A pool of `workers` threads (at least one) and `queue` waiting places.
    /// The threads end when the last clone of the pool is dropped.
    pub fn new(workers: usize, queue: usize) -> Self {
        let workers = workers.max(1);
        let (jobs, inbox) = mpsc::channel::<Message>();
        let inbox = Arc::new(Mutex::new(inbox));
        let busy = Arc::new(AtomicUsize::new(0));
        let alive = Arc::new(Alive::default());
        for i in 0..workers {
            let (inbox, busy, alive) = (inbox.clone(), busy.clone(), alive.clone());
            *alive.count.lock().expect("never poisoned") += 1;
            std::thread::Builder::new()
                .name(format!("bowloc-worker-{i}"))
                .spawn(move || {
                    work(&inbox, &busy);
                    *alive.count.lock().expect("never poisoned") -= 1;
                    alive.ended.notify_all();
                })
                .expect("spawning a worker thread");
        }
        Self {
            jobs,
            alive,
            admitted: Arc::new(Semaphore::new(workers + queue)),
            busy,
            workers,
            queue,
        }
    }

    pub fn workers(&self) -> usize {
        self.workers
    }

    pub fn queue_capacity(&self) -> usize {
        self.queue
    }

    /// Jobs admitted and not finished (running or waiting).
    pub fn admitted(&self) -> usize {
        self.workers + self.queue - self.admitted.available_permits()
    }

    /// Jobs running now.
    pub fn busy(&self) -> usize {
        self.busy.load(Ordering::Relaxed)
    }

    /// Run `job` on a worker once one is free. Refused at once with
    /// [`PoolError::QueueFull`] when `workers + queue` jobs are admitted; gives
    /// up with [`PoolError::TimedOut`] if `deadline` passes while the job
    /// waits for a worker (a job admitted while a worker is free never waits).
    /// Once started the job runs to its end even if the caller goes away,
    /// holding its place until then.
    pub async fn run<T, F>(&self, deadline: Option<Instant>, job: F) -> Result<T, PoolError>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        let ticket = self
            .admitted
            .clone()
            .try_acquire_owned()
            .map_err(|_| PoolError::QueueFull)?;
        let waits = self.admitted() > self.workers;
        let (done, result) = oneshot::channel();
        let place = Arc::new(Place {
            progress: AtomicU8::new(WAITING),
            ticket: Mutex::new(Some(ticket)),
        });
        let work: Work = Box::new(move || {
            let result = catch_unwind(AssertUnwindSafe(job));
            Box::new(move || {
                let _ = done.send(result);
            })
        });
        self.jobs
            .send(Message::Job(Job {
                work,
                place: place.clone(),
            }))
            .map_err(|_| PoolError::Panicked("the workers have stopped".into()))?;
        let result = match deadline.filter(|_| waits) {
            None => result.await,
            Some(d) => {
                let mut result = result;
                match tokio::time::timeout_at(d, &mut result).await {
                    Ok(r) => r,
                    Err(_) => {
                        if place.claim(ABANDONED) {
                            place.release();
                            return Err(PoolError::TimedOut);
                        }
                        result.await
                    }
                }
            }
        };
        match result {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(panic)) => Err(PoolError::Panicked(panic_message(panic.as_ref()))),
            Err(_) => Err(PoolError::Panicked("the worker stopped".into())),
        }
    }
}

impl WorkerPool {
    /// Run `job` once on every worker and wait for them all: work that
    /// prepares a worker's thread, before the service takes requests. A
    /// worker that takes its job waits, up to `meet`, for the others to take
    /// theirs, so that none takes two (one busy with something else that
    /// long lets another take its turn).
    pub async fn on_every_worker<T: Send + 'static>(
        &self,
        meet: Duration,
        job: impl Fn() -> T + Send + Sync + 'static,
    ) -> Vec<Result<T, PoolError>> {
        let job = Arc::new(job);
        let met = Arc::new((Mutex::new(0usize), Condvar::new()));
        let mut all = tokio::task::JoinSet::new();
        for _ in 0..self.workers {
            let (pool, job, met, n) = (self.clone(), job.clone(), met.clone(), self.workers);
            all.spawn(async move {
                let once = move || {
                    let (here, all_here) = &*met;
                    let mut count = here.lock().expect("never poisoned");
                    *count += 1;
                    all_here.notify_all();
                    drop(all_here.wait_timeout_while(count, meet, |count| *count < n));
                    job()
                };
                pool.run(None, once).await
            });
        }
        all.join_all().await
    }
}

impl WorkerPool {
    /// Stop the workers once the jobs already queued are done, and wait up to
    /// `timeout` for them to end. Returns whether they all did. For the end
    /// of the service, once no more jobs will come.
    pub fn close(&self, timeout: Duration) -> bool {
        for _ in 0..self.workers {
            let _ = self.jobs.send(Message::Stop);
        }
        let count = self.alive.count.lock().expect("never poisoned");
        let (count, _) = self
            .alive
            .ended
            .wait_timeout_while(count, timeout, |n| *n > 0)
            .expect("never poisoned");
        *count == 0
    }
}

/// A worker thread: take jobs until told to stop or the pool is gone, and
/// skip those abandoned while waiting.
fn work(inbox: &Mutex<mpsc::Receiver<Message>>, busy: &AtomicUsize) {
    loop {
        let next = inbox
            .lock()
            .map_err(drop)
            .and_then(|rx| rx.recv().map_err(drop));
        let Ok(Message::Job(job)) = next else { return };
        if !job.place.claim(STARTED) {
            continue;
        }
        busy.fetch_add(1, Ordering::Relaxed);
        let deliver = (job.work)();
        busy.fetch_sub(1, Ordering::Relaxed);
        // The place is free before the caller hears of the result.
        job.place.release();
        deliver();
    }
}

/// The message of a panic payload.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    /// A job that blocks until released, and tells when it has started.
    fn blocking_job(
        pool: &WorkerPool,
    ) -> (
        tokio::task::JoinHandle<Result<u32, PoolError>>,
        mpsc::Sender<()>,
        tokio::sync::oneshot::Receiver<()>,
    ) {
        let (release, wait) = mpsc::channel::<()>();
        let (started_tx, started) = tokio::sync::oneshot::channel();
        let pool = pool.clone();
        let handle = tokio::spawn(async move {
            pool.run(None, move || {
                let _ = started_tx.send(());
                wait.recv().unwrap();
                7
            })
            .await
        });
        (handle, release, started)
    }

    #[tokio::test]
    async fn every_worker_runs_the_job_once() {
        let pool = WorkerPool::new(3, 0);
        let name = || std::thread::current().name().map(String::from);
        let mut ran: Vec<_> = pool
            .on_every_worker(Duration::from_secs(10), name)
            .await
            .into_iter()
            .map(|r| r.unwrap().unwrap())
            .collect();
        ran.sort();
        assert_eq!(
            ran,
            ["bowloc-worker-0", "bowloc-worker-1", "bowloc-worker-2"]
        );
        // and the pool is as before
        assert_eq!((pool.busy(), pool.admitted()), (0, 0));
    }

    #[tokio::test]
    async fn a_busy_worker_lets_another_take_its_turn() {
        let pool = WorkerPool::new(2, 2);
        let (blocked, release, started) = blocking_job(&pool);
        started.await.unwrap();
        let ran = pool.on_every_worker(Duration::from_millis(50), || 1).await;
        assert_eq!(ran, [Ok(1), Ok(1)]);
        release.send(()).unwrap();
        assert_eq!(blocked.await.unwrap(), Ok(7));
    }

    #[tokio::test]
    async fn refuses_beyond_workers_plus_queue() {
        let pool = WorkerPool::new(1, 1);
        let (first, release_first, started) = blocking_job(&pool);
        started.await.unwrap();
        assert_eq!(pool.busy(), 1);
        // The second waits in the queue...
        let queued = {
            let pool = pool.clone();
            tokio::spawn(async move { pool.run(None, || 8).await })
        };
        while pool.admitted() < 2 {
            tokio::task::yield_now().await;
        }
        // ...and a third is refused at once.
        assert_eq!(pool.run(None, || 9).await, Err(PoolError::QueueFull));
        release_first.send(()).unwrap();
        assert_eq!(first.await.unwrap(), Ok(7));
        assert_eq!(queued.await.unwrap(), Ok(8));
        assert_eq!(pool.admitted(), 0);
        assert_eq!(pool.run(None, || 10).await, Ok(10));
    }

    #[tokio::test]
    async fn gives_up_waiting_at_the_deadline() {
        let pool = WorkerPool::new(1, 4);
        let (first, release, started) = blocking_job(&pool);
        started.await.unwrap();
        let past = Instant::now();
        assert_eq!(pool.run(Some(past), || 1).await, Err(PoolError::TimedOut));
        release.send(()).unwrap();
        first.await.unwrap().unwrap();
        // With a free worker a passed deadline does not refuse the job.
        assert_eq!(pool.run(Some(past), || 2).await, Ok(2));
    }

    #[tokio::test]
    async fn a_job_abandoned_while_waiting_never_runs_and_frees_its_place() {
        use std::sync::atomic::AtomicBool;
        let pool = WorkerPool::new(1, 2);
        let (first, release, started) = blocking_job(&pool);
        started.await.unwrap();
        let ran = Arc::new(AtomicBool::new(false));
        let soon = Instant::now() + std::time::Duration::from_millis(20);
        let job = {
            let ran = ran.clone();
            move || ran.store(true, Ordering::SeqCst)
        };
        assert_eq!(pool.run(Some(soon), job).await, Err(PoolError::TimedOut));
        release.send(()).unwrap();
        first.await.unwrap().unwrap();
        // Jobs are taken in order, so this one runs after the abandoned one
        // was taken off the queue.
        assert_eq!(pool.run(None, || 5).await, Ok(5));
        assert!(!ran.load(Ordering::SeqCst));
        assert_eq!(pool.admitted(), 0);
    }

    #[tokio::test]
    async fn a_panicking_job_is_an_error_and_frees_its_place() {
        let pool = WorkerPool::new(1, 0);
        let r = pool.run(None, || -> u32 { panic!("boom") }).await;
        assert_eq!(r, Err(PoolError::Panicked("boom".into())));
        assert_eq!(pool.admitted(), 0);
        assert_eq!(pool.run(None, || 3).await, Ok(3));
    }
}
